//! Run-time choice between the AVX2/FMA kernels and the portable ones.
//!
//! The hot kernels (IDSVA-SO, the multi-right-hand-side `LᵀDL` solves, IDFOZA and the `M⁻¹`
//! products in FD-SO, the gemm (with its masked-tail variant), transposes and the SPD inverse of
//! the Delassus matrix) have an AVX2/FMA version compiled with `#[target_feature]` and a portable
//! version; [`avx2_fma`] picks one per call. The `M⁻¹` products of FD-SO and its IDFOZA passes
//! (eight right-hand sides per pass instead of four) also have an AVX-512F version, picked by
//! [`avx512f`]. All give the same results to rounding: the unit test below forces the
//! portable path (and the AVX2 one) and compares.

/// Test switch: run the portable kernels even where AVX2/FMA is available.
#[cfg(test)]
pub(crate) static FORCE_PORTABLE: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Test switch: run the AVX2/FMA kernels where AVX-512 kernels exist and are available.
#[cfg(test)]
pub(crate) static FORCE_AVX2: std::sync::atomic::AtomicBool =
    std::sync::atomic::AtomicBool::new(false);

/// Whether the AVX-512F kernels may run (the CPU has AVX-512F and the AVX2/FMA kernels may
/// run). Only some kernels have an AVX-512 version; they fall back to AVX2/FMA, then portable.
#[inline]
pub(crate) fn avx512f() -> bool {
    #[cfg(test)]
    if FORCE_AVX2.load(std::sync::atomic::Ordering::Relaxed) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        avx2_fma() && std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Whether the AVX2/FMA kernels may run (the CPU has both features; the result is cached by the
/// standard library's feature detection).
#[inline]
pub(crate) fn avx2_fma() -> bool {
    #[cfg(test)]
    if FORCE_PORTABLE.load(std::sync::atomic::Ordering::Relaxed) {
        return false;
    }
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

#[cfg(test)]
mod tests {
    use super::{FORCE_AVX2, FORCE_PORTABLE};
    use crate::algo::{Contact, Data};
    use crate::deriv::{
        ContactData, FdSoData, ImpactData, KktData, SoData, fd_derivatives, fd_so_derivatives,
        id_derivatives, id_so_derivatives, impact_derivatives, kkt_derivatives,
    };
    use crate::model::Model;
    use crate::model::builtin::{pendulum, quadruped, random_tree, serial_chain};
    use crate::rng::Rng;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector, Vector3};
    use std::sync::atomic::Ordering::Relaxed;

    /// Every output of the algorithms with AVX2/FMA kernels, as one list of flat vectors.
    fn outputs(
        m: &Model,
        feet: &[&str],
        q: &DVector<f64>,
        v: &DVector<f64>,
        u: &DVector<f64>,
    ) -> Vec<Vec<f64>> {
        let mat = |x: &DMatrix<f64>| x.as_slice().to_vec();
        let ten = |x: &Tensor3| x.as_slice().to_vec();
        let mut out = vec![];
        let mut d = Data::new(m);
        out.push(mat(crate::algo::crba(m, &mut d, q).unwrap()));
        out.push(crate::algo::aba(m, &mut d, q, v, u, None).unwrap().as_slice().to_vec());
        id_derivatives(m, &mut d, q, v, u, None).unwrap();
        out.extend([mat(&d.dtau_dq), mat(&d.dtau_dv), mat(&d.m)]);
        let mut so = SoData::new(m);
        id_so_derivatives(m, &mut d, &mut so, q, v, u, None).unwrap();
        out.extend([
            ten(so.d2tau_dq2()),
            ten(so.d2tau_dv2()),
            ten(so.d2tau_dqdv()),
            ten(so.dm_dq()),
        ]);
        fd_derivatives(m, &mut d, q, v, u, None).unwrap();
        out.extend([mat(&d.dqdd_dq), mat(&d.dqdd_dv), mat(&d.minv)]);
        let mut fso = FdSoData::new(m);
        fd_so_derivatives(m, &mut d, &mut fso, q, v, u, None).unwrap();
        out.extend([
            ten(fso.d2qdd_dq2()),
            ten(fso.d2qdd_dv2()),
            ten(fso.d2qdd_dqdv()),
            ten(fso.d2qdd_dtaudq()),
        ]);
        if !feet.is_empty() {
            let cs: Vec<Contact> =
                feet.iter().map(|f| Contact::new(m, f, Vector3::zeros()).unwrap()).collect();
            let cd = ContactData::new(m, &cs).unwrap();
            let mut kd = KktData::new(m, cd.clone());
            kkt_derivatives(m, &mut d, &mut kd, q, v, u).unwrap();
            out.extend([
                mat(&kd.dqdd_dq),
                mat(&kd.dqdd_dv),
                mat(&kd.dlambda_dq),
                mat(&kd.dqdd_dtau),
                mat(&kd.dlambda_dv),
                mat(&kd.dlambda_dtau),
            ]);
            let mut im = ImpactData::new(m, cd);
            impact_derivatives(m, &mut d, &mut im, q, v).unwrap();
            out.extend([
                mat(&im.dvplus_dq),
                mat(&im.dvplus_dvminus),
                mat(&im.dimpulse_dq),
                mat(&im.dimpulse_dvminus),
                im.vplus.as_slice().to_vec(),
            ]);
        }
        out
    }

    /// The portable kernels and the AVX2/FMA ones give the same results (to rounding).
    #[test]
    fn portable_and_simd_kernels_agree() {
        let mut rng = Rng::new(5);
        let quad = quadruped();
        let cases: Vec<(Model, Vec<&str>)> = vec![
            (random_tree(6, 83, false), vec![]),
            (random_tree(14, 91, true), vec![]),
            // nv > 48: the FD-SO products split the rows of M⁻¹ into several chunks.
            (random_tree(53, 17, true), vec![]),
            // Revolute joints about ±eₖ: angles not contiguous in q (two chunks of the 4-lane
            // sin/cos), and contiguous with a partial chunk.
            (serial_chain(7), vec![]),
            (pendulum(3), vec![]),
            (quad, vec!["LF_FOOT", "RF_FOOT", "LH_FOOT"]),
        ];
        for (m, feet) in &cases {
            let q = m.random_configuration(&mut rng);
            let v = DVector::from_fn(m.nv, |_, _| rng.range(-1.0, 1.0));
            let u = DVector::from_fn(m.nv, |_, _| rng.range(-1.0, 1.0));
            let simd = outputs(m, feet, &q, &v, &u);
            FORCE_AVX2.store(true, Relaxed);
            let avx2 = outputs(m, feet, &q, &v, &u);
            FORCE_AVX2.store(false, Relaxed);
            FORCE_PORTABLE.store(true, Relaxed);
            let portable = outputs(m, feet, &q, &v, &u);
            FORCE_PORTABLE.store(false, Relaxed);
            for (what, fast) in [("SIMD", &simd), ("AVX2", &avx2)] {
                for (k, (a, b)) in fast.iter().zip(&portable).enumerate() {
                    let scale = a.iter().fold(1.0f64, |s, x| s.max(x.abs()));
                    let err = a.iter().zip(b).fold(0.0f64, |e, (x, y)| e.max((x - y).abs()));
                    assert!(
                        err <= 1e-10 * scale,
                        "{}: {what} output {k} differs by {err:e}",
                        m.name
                    );
                }
            }
        }
    }
}
