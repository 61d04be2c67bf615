//! Zero-velocity shortcuts: IDFOZA (`∂M/∂q · x` from the first-order ID derivatives at `q̇ = 0`,
//! no gravity, `q̈ = x`; `O(N d)`) and IDSOZA (`∂²M/∂q² · x` from IDSVA-SO at `q̇ = 0`, no gravity,
//! `q̈ = x`; eq. eqn_IDSOZAc without contact forces). They replace `O(N⁴)` tensor products in the
//! forward-dynamics, KKT and impact second-order derivatives.
//!
//! [`idfoza`]: inputs model, configuration `q`, vector `x` (length `nv`). Output
//! `out[(i, k)] = ∂(M(q) x)_i/∂q_k` (`nv × nv`, tangent space; entries of DoFs on different
//! branches zero). IDSVA (see [`super::id_fo`]) at `q̇ = 0`, `a_0 = 0`, `q̈ = x`, where
//! `τ = M x`, `v = 0`, `Ψ̇ = 0`, `Ṡ = 0` and `B = 0`; ground frame:
//! 1. placements `⁰M_i`, world subspaces `S_c = ⁰X_i S_c^i`, world body inertias
//!    `I_i = ⁰X_i^* I_i^i ⁱX_0`, composites `I^C_i = Σ_{k ⪰ i} I_k`;
//! 2. forward pass, `i = 1..N`, from `a_0 = 0`: `Ψ̈_c = a_λ × S_c` for the DoFs `c` of joint `i`
//!    (eq. psidot_psidotdot_defn at `v = 0`), `a_i = a_λ + Σ_c S_c x_c`, `f_i = I_i a_i`;
//! 3. backward pass, `i = N..1`, with `f^C_i = Σ_{k ⪰ i} f_k`: for each DoF `c` of joint `i`,
//!    `t₁ = I^C_i S_c`, `t₃ = I^C_i Ψ̈_c + f^C_i ×̄* S_c`; `out[(c, r)] = t₁·Ψ̈_r` for the DoFs
//!    `r` of joint `i` and of its ancestors (eq. dtau_dq_1 with `B = 0`, `Ψ̇ = 0`),
//!    `out[(r, c)] = S_r·t₃` for the DoFs `r` of its strict ancestors (eq. dtau_dq_2 with
//!    `B = 0`, `Ψ̇ = 0`); then `f^C_λ += f^C_i`.
//!
//! [`idsoza`]: inputs model, `q`, `x`, an [`SoData`] as workspace. Output
//! `∂²(M(q) x)/∂q²` (`T[(i, j, k)] = ∂/∂q_k ∂(M x)_i/∂q_j`, the `d2tau_dq2` tensor of the
//! workspace): IDSVA-SO ([`super::id_so`]) at `(q, q̇ = 0, q̈ = x)` with no gravity (`a_0 = 0`)
//! and no external forces, which gives `∂²τ/∂q² = ∂²(M x)/∂q²` (eq. eqn_IDSOZAc with `λ = 0`).

use super::id_so::{SoData, id_so_unchecked};
use crate::algo::Data;
use crate::algo::data::Part;
use crate::algo::internal::placements;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::spatial::Motion;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};

pub(crate) use crate::simd::Lanes;
#[cfg(target_arch = "x86_64")]
pub(crate) use crate::simd::{Avx4, Avx8};

/// IDFOZA: writes `out[(i, k)] = Σ_l ∂M_il/∂q_k x_l = ∂(M(q) x)_i/∂q_k` (tangent space).
/// `out` must be `nv×nv`.
pub fn idfoza(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    x: &DVector<f64>,
    out: &mut DMatrix<f64>,
) -> Result<()> {
    if let Some(r) = &model.reduction {
        return crate::deriv::zero::reduced::idfoza(r, data.reduced(model)?, q, x, out);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("x", x, model.nv)?;
    if out.shape() != (model.nv, model.nv) {
        return Err(Error::Dimension {
            what: "out (rows·cols)".into(),
            expected: model.nv * model.nv,
            got: out.len(),
        });
    }
    placements(model, data, q);
    for i in 1..model.njoints() {
        let xf = data.o_m_i[i];
        let inertia = xf.act_inertia(&model.inertias[i]);
        data.oinertia[i] = inertia;
        data.ic_world[i] = inertia;
        for c in model.idx_v[i]..model.idx_v[i] + model.nvs[i] {
            data.s_world[c] = xf.act_motion(&model.subspace[c]);
        }
    }
    for i in (1..model.njoints()).rev() {
        let p = model.parents[i];
        if p > 0 {
            let ic = data.ic_world[i];
            data.ic_world[p] += ic;
        }
    }
    out.fill(0.0);
    idfoza_core(model, data, x.as_slice(), out);
    Ok(())
}

/// IDFOZA core: needs `s_world`, body inertias `oinertia` and composite inertias `ic_world`
/// (world frame) for the current `q` in `data`. Uses the `z_*` workspaces only.
pub(crate) fn idfoza_core(model: &Model, data: &mut Data, x: &[f64], out: &mut DMatrix<f64>) {
    let nv = model.nv;
    assert!(out.shape() == (nv, nv), "idfoza_core: out must be nv×nv");
    let o = out.as_mut_slice();
    // SAFETY: `put` is only called with DoF indices c, r < nv, so c + nv r < nv² = o.len().
    idfoza_core_with(model, data, x, |c, r, v| unsafe { *o.get_unchecked_mut(c + nv * r) = v });
}

/// IDFOZA core writing through `put(i, k, ∂(M x)_i/∂q_k)`, called once for each structurally
/// non-zero entry (`i`, `k` on one root path); the other entries are zero.
#[inline(always)]
pub(crate) fn idfoza_core_with(
    model: &Model,
    data: &mut Data,
    x: &[f64],
    mut put: impl FnMut(usize, usize, f64),
) {
    let n = model.njoints();
    data.z_a[0] = Motion::zero();
    for i in 1..n {
        let ap = data.z_a[model.parents[i]];
        let mut ai = ap;
        let iv = model.idx_v[i];
        for (c, xc) in x.iter().enumerate().skip(iv).take(model.nvs[i]) {
            let s = data.s_world[c];
            data.z_psidd[c] = ap.cross(&s); // Ψ̈ at q̇ = 0
            ai += s * *xc;
        }
        data.z_a[i] = ai;
        data.z_fc[i] = data.oinertia[i].mul_motion(&ai);
    }
    let nv = model.nv;
    assert!(
        data.s_world.len() == nv
            && data.z_psidd.len() == nv
            && model.dof_ancestors_start.len() == nv + 1,
        "idfoza_core: workspace built for another model"
    );
    for i in (1..n).rev() {
        let ic = data.ic_world[i];
        let fc = data.z_fc[i];
        let iv = model.idx_v[i];
        let ive = iv + model.nvs[i];
        for c in iv..ive {
            let s = data.s_world[c];
            let t1 = ic.mul_motion(&s);
            let psidd = &data.z_psidd;
            let sw = &data.s_world;
            // dtau_dq_1 with B = 0, Ψ̇ = 0: the DoFs of joint i itself...
            for (r, p) in psidd.iter().enumerate().take(ive).skip(iv) {
                put(c, r, t1.dot(p));
            }
            // dtau_dq_2 with B = 0, Ψ̇ = 0
            let t3 = ic.mul_motion(&psidd[c]) + fc.crff(&s);
            // ... and of the strict ancestor joints (ancestor DoFs below `iv`), both terms.
            for &r in model.ancestors_of_dof(c) {
                if r < iv {
                    // SAFETY: ancestor DoFs are < c < nv = psidd.len() = sw.len() (asserted).
                    let (pr, sr) = unsafe { (psidd.get_unchecked(r), sw.get_unchecked(r)) };
                    put(c, r, t1.dot(pr));
                    put(r, c, sr.dot(&t3));
                }
            }
        }
        let p = model.parents[i];
        if p > 0 {
            data.z_fc[p] += fc;
        }
    }
}

/// IDSOZA: `out[(i, j, k)] = ∂/∂q_k ∂(M(q) x)_i/∂q_j` (eq. eqn_IDSOZAc with `λ = 0`), from
/// IDSVA-SO at `q̇ = 0`, no gravity, `q̈ = x`; `data` made by [`Data::with_second_order`]
/// (whose `d2tau_dq2` tensor it fills and returns).
///
/// # Errors
/// As [`Model::check_q`]; `x` of the wrong length or not finite; [`crate::Error::Workspace`]
/// for a `data` of another model or without second-order capacity.
pub fn idsoza<'a>(
    model: &Model,
    data: &'a mut Data,
    q: &DVector<f64>,
    x: &DVector<f64>,
) -> Result<&'a Tensor3> {
    let f = "idsoza";
    data.with_part(Part::IdSo, f, "Data::with_second_order", |data, so: &mut SoData| {
        idsoza_ws(model, data, so, q, x).map(|_| ())
    })?;
    Ok(data.part_or::<SoData>(Part::IdSo, f)?.d2tau_dq2())
}

/// [`idsoza`] with its workspace part passed apart.
pub(crate) fn idsoza_ws<'a>(
    model: &Model,
    data: &mut Data,
    so: &'a mut SoData,
    q: &DVector<f64>,
    x: &DVector<f64>,
) -> Result<&'a Tensor3> {
    if let Some(r) = &model.reduction {
        let so = crate::algo::data::reduced::reduced_ws(&mut so.red, "SoData", model)?;
        return crate::deriv::zero::reduced::idsoza(r, data.reduced(model)?, so, q, x);
    }
    model.check_q(q)?;
    data.check_tree(model)?;
    check_vec("x", x, model.nv)?;
    so.check_tree(model)?;
    let mut zero = std::mem::replace(&mut data.tmp_v, DVector::zeros(0));
    zero.fill(0.0);
    id_so_unchecked(model, data, so, q, &zero, x, None, Motion::zero());
    data.tmp_v = zero;
    Ok(so.d2tau_dq2())
}

/// Workspace of [`idfoza_lanes_core`] for right-hand sides in lanes `A` (`[f64; 4]` or
/// `[f64; 8]`): joint accelerations, `Ψ̈` per DoF and composite forces, component `m`
/// (`[ang; lin]`) of lane `l` at `[m][l]`.
#[derive(Clone, Debug)]
pub(crate) struct IdfozaWs<A> {
    a: Vec<[A; 6]>,
    psidd: Vec<[A; 6]>,
    fc: Vec<[A; 6]>,
    /// `root[c]`: DoF `c` belongs to a joint attached to the world (its `Ψ̈` vanishes).
    root: Vec<bool>,
}

impl<A: Copy + Default> IdfozaWs<A> {
    pub(crate) fn new(model: &Model) -> Self {
        let z = [A::default(); 6];
        Self {
            a: vec![z; model.njoints()],
            psidd: vec![z; model.nv],
            fc: vec![z; model.njoints()],
            root: (0..model.nv).map(|c| model.parents[model.dof_joint[c]] == 0).collect(),
        }
    }
}

#[inline(always)]
pub(crate) fn v6(ang: &nalgebra::Vector3<f64>, lin: &nalgebra::Vector3<f64>) -> [f64; 6] {
    [ang.x, ang.y, ang.z, lin.x, lin.y, lin.z]
}

#[inline(always)]
fn ld6<V: Lanes>(a: &[V::Arr; 6]) -> [V; 6] {
    [V::load(&a[0]), V::load(&a[1]), V::load(&a[2]), V::load(&a[3]), V::load(&a[4]), V::load(&a[5])]
}

#[inline(always)]
fn st6<V: Lanes>(a: &[V; 6]) -> [V::Arr; 6] {
    [a[0].store(), a[1].store(), a[2].store(), a[3].store(), a[4].store(), a[5].store()]
}

/// `a × b` for lane 3-vectors `a` and a plain `b`.
#[inline(always)]
fn cross_lp<V: Lanes>(a: &[V], b: &[f64]) -> [V; 3] {
    let s = [V::splat(b[0]), V::splat(b[1]), V::splat(b[2])];
    [
        a[1].mul(s[2]).sub(a[2].mul(s[1])),
        a[2].mul(s[0]).sub(a[0].mul(s[2])),
        a[0].mul(s[1]).sub(a[1].mul(s[0])),
    ]
}

/// `a × b` for a plain `a` and lane 3-vectors `b`.
#[inline(always)]
pub(crate) fn cross_pl<V: Lanes>(a: &[f64], b: &[V]) -> [V; 3] {
    let s = [V::splat(a[0]), V::splat(a[1]), V::splat(a[2])];
    [
        s[1].mul(b[2]).sub(s[2].mul(b[1])),
        s[2].mul(b[0]).sub(s[0].mul(b[2])),
        s[0].mul(b[1]).sub(s[1].mul(b[0])),
    ]
}

#[inline(always)]
pub(crate) fn add3<V: Lanes>(a: &mut [V], b: [V; 3]) {
    for (a, b) in a.iter_mut().zip(b) {
        *a = a.add(b);
    }
}

/// `s ×* f` (force cross product) of a plain `s` and lane vectors `f`.
#[inline(always)]
pub(crate) fn cross_force_lanes<L: Lanes>(s: &[f64; 6], f: &[L; 6]) -> [L; 6] {
    let mut ang = cross_pl(&s[..3], &f[..3]);
    add3(&mut ang, cross_pl(&s[3..], &f[3..]));
    let lin = cross_pl(&s[..3], &f[3..]);
    [ang[0], ang[1], ang[2], lin[0], lin[1], lin[2]]
}

/// `I v` (eq. of [`crate::spatial::Inertia::mul_motion`]) on lanes.
#[inline(always)]
pub(crate) fn inertia_mul_l<V: Lanes>(inr: &crate::spatial::Inertia, v: &[V; 6]) -> [V; 6] {
    let h = [inr.h.x, inr.h.y, inr.h.z];
    let hl = cross_pl(&h, &v[3..6]); // h × v.lin
    let ha = cross_pl(&h, &v[0..3]); // h × v.ang
    let mass = V::splat(inr.mass);
    let mut out = [mass; 6];
    for m in 0..3 {
        let (r0, r1, r2) =
            (V::splat(inr.rot[(m, 0)]), V::splat(inr.rot[(m, 1)]), V::splat(inr.rot[(m, 2)]));
        out[m] = r0.mul_add(v[0], r1.mul_add(v[1], r2.mul_add(v[2], hl[m])));
        out[3 + m] = v[3 + m].mul(mass).sub(ha[m]);
    }
    out
}

/// Lane-wise pairing `Σ_m p[m] v[m]`.
#[inline(always)]
fn dot_pl<V: Lanes>(p: &[f64; 6], v: &[V; 6]) -> V::Arr {
    let s = [
        V::splat(p[0]),
        V::splat(p[1]),
        V::splat(p[2]),
        V::splat(p[3]),
        V::splat(p[4]),
        V::splat(p[5]),
    ];
    let a = s[0].mul_add(v[0], s[1].mul(v[1]));
    let b = s[2].mul_add(v[2], s[3].mul(v[3]));
    let c = s[4].mul_add(v[4], s[5].mul(v[5]));
    a.add(b).add(c).store()
}

/// IDFOZA ([`idfoza_core_with`]) for `N` right-hand sides at once (the lanes of `V`),
/// vectorised across them: lane `l` uses `x[c + ldx (j0 + l)]` for `l < nl` (zero otherwise) and
/// `put(i, k, z)` receives `z[l] = ∂(M x_l)_i/∂q_k`, for the structurally non-zero `(i, k)` but
/// those where `k` is a DoF of a joint attached to the world: `∂M/∂q_k = 0` there (its `Ψ̈ = a₀ ×
/// s = 0` at `q̇ = 0`), so they are left to the caller's zeros. Needs the same `data` fields as
/// [`idfoza_core`] (read only). The lanes are `V`: `[f64; 4]` anywhere, [`Avx4`] only inside
/// functions compiled with AVX2 and FMA, [`Avx8`] only inside functions compiled with
/// AVX-512F (behind the run-time checks).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn idfoza_lanes_core<V: Lanes>(
    model: &Model,
    data: &Data,
    ws: &mut IdfozaWs<V::Arr>,
    x: &[f64],
    ldx: usize,
    j0: usize,
    nl: usize,
    mut put: impl FnMut(usize, usize, &V::Arr),
) {
    let n = model.njoints();
    let nv = model.nv;
    let lanes = V::Arr::default().as_ref().len();
    assert!(
        nl <= lanes
            && (nl == 0 || ldx * (j0 + nl - 1) + nv <= x.len())
            && ws.a.len() == n
            && ws.psidd.len() == nv
            && data.s_world.len() == nv,
        "idfoza_lanes_core: dimension mismatch"
    );
    ws.a[0] = [V::Arr::default(); 6];
    for i in 1..n {
        let ap: [V; 6] = ld6(&ws.a[model.parents[i]]);
        let mut ai = ap;
        let iv = model.idx_v[i];
        for c in iv..iv + model.nvs[i] {
            let s = &data.s_world[c];
            let sv = v6(&s.ang, &s.lin);
            // Ψ̈ = a_λ × s at q̇ = 0
            let pa = cross_lp(&ap[0..3], &sv[0..3]);
            let mut pl = cross_lp(&ap[0..3], &sv[3..6]);
            add3(&mut pl, cross_lp(&ap[3..6], &sv[0..3]));
            ws.psidd[c] = st6(&[pa[0], pa[1], pa[2], pl[0], pl[1], pl[2]]);
            let mut xl = V::Arr::default();
            for (l, v) in xl.as_mut().iter_mut().enumerate().take(nl) {
                *v = x[c + ldx * (j0 + l)];
            }
            let xl = V::load(&xl);
            for m in 0..6 {
                ai[m] = V::splat(sv[m]).mul_add(xl, ai[m]);
            }
        }
        ws.a[i] = st6(&ai);
        ws.fc[i] = st6(&inertia_mul_l(&data.oinertia[i], &ai));
    }
    assert!(ws.root.len() == nv, "idfoza_lanes_core: dimension mismatch");
    for i in (1..n).rev() {
        let ic = &data.ic_world[i];
        let fc: [V; 6] = ld6(&ws.fc[i]);
        let iv = model.idx_v[i];
        let ive = iv + model.nvs[i];
        // A joint attached to the world: Ψ̈ = 0 for its DoFs.
        let at_root = model.parents[i] == 0;
        for c in iv..ive {
            let s = &data.s_world[c];
            let t1f = ic.mul_motion(s);
            let t1 = v6(&t1f.ang, &t1f.lin);
            // dtau_dq_1 with B = 0, Ψ̇ = 0: the DoFs of joint i itself...
            for r in (iv..ive).filter(|_| !at_root) {
                put(c, r, &dot_pl::<V>(&t1, &ld6(&ws.psidd[r])));
            }
            // dtau_dq_2 with B = 0, Ψ̇ = 0: t3 = Ic Ψ̈_c + s ×* f_c
            let mut t3 = inertia_mul_l(ic, &ld6::<V>(&ws.psidd[c]));
            let sf = cross_force_lanes(&v6(&s.ang, &s.lin), &fc);
            for (t, x) in t3.iter_mut().zip(sf) {
                *t = t.add(x);
            }
            // ... and of the strict ancestor joints (ancestor DoFs below `iv`), both terms.
            for &r in model.ancestors_of_dof(c) {
                if r < iv {
                    // SAFETY: ancestor DoFs are < c < nv = psidd.len() = s_world.len() =
                    // root.len() (asserted).
                    let (pr, sr, root) = unsafe {
                        (
                            ws.psidd.get_unchecked(r),
                            data.s_world.get_unchecked(r),
                            *ws.root.get_unchecked(r),
                        )
                    };
                    if !root {
                        put(c, r, &dot_pl::<V>(&t1, &ld6(pr)));
                    }
                    put(r, c, &dot_pl(&v6(&sr.ang, &sr.lin), &t3));
                }
            }
        }
        let p = model.parents[i];
        if p > 0 {
            let mut fp: [V; 6] = ld6(&ws.fc[p]);
            for (a, b) in fp.iter_mut().zip(&fc) {
                *a = a.add(*b);
            }
            ws.fc[p] = st6(&fp);
        }
    }
}

/// The reduced coordinates of a model with mimic joints ([`crate::model::Model::is_reduced`]):
/// the full tree's functions of this family at `q_full = expand(q)`, `G v`, `G a`, reduced
/// with `G` (see `crate::model::reduction` and docs/conventions.md, "Mimic joints").
pub(crate) mod reduced {

    use crate::error::{Error, Result};

    use crate::model::reduction::MimicModel;
    use crate::tensor::Tensor3;
    use nalgebra::{DMatrix, DVector};

    use crate::algo::data::reduced::MimicData;
    use crate::algo::data::reduced::prepare;
    use crate::deriv::id_so::reduced::MimicSoData;

    /// IDFOZA in the reduced coordinates: `out[(i, k)] = ∂(M(q) x)_i/∂q_k` (`nv × nv`, tangent
    /// space), with `M = Gᵀ M_full(expand(q)) G`: `out = Gᵀ [∂(M_full y)/∂q_full] G` at `y = G x`
    /// (the full tree's [`crate::deriv::idfoza`]). Leaves `expand(q)`, zero velocity and `G x` in
    /// `data.q_full()`, `data.v_full()`, `data.a_full()`. Allocates nothing.
    ///
    /// # Errors
    /// As [`crba`] for `q`; `x` of the wrong length or not finite; `out` not `nv × nv`.
    pub fn idfoza(
        model: &MimicModel,
        data: &mut MimicData,
        q: &DVector<f64>,
        x: &DVector<f64>,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        prepare(model, data, q, None, Some(("x", x)))?;
        if out.shape() != (model.nv, model.nv) {
            return Err(Error::Dimension {
                what: "out (rows·cols)".into(),
                expected: model.nv * model.nv,
                got: out.len(),
            });
        }
        model.expand_v_into(x.as_slice(), data.a.as_mut_slice());
        crate::deriv::idfoza(&model.full, &mut data.full, &data.q, &data.a, &mut data.mf)?;
        model.reduce_matrix(&data.mf, out);
        Ok(())
    }

    /// IDSOZA in the reduced coordinates: `T[(i, j, k)] = ∂/∂q_k ∂(M(q) x)_i/∂q_j` (tangent
    /// space, nested as the other second-order tensors), the full tree's
    /// [`crate::deriv::idsoza`] at `expand(q)`, `y = G x` contracted with `Gᵀ` on `i` and `G` on
    /// `j` and `k`. Writes and returns `so.d2tau_dq2()` (the other tensors of `so` are not
    /// written); the state in `data` as [`idfoza`]. Allocates nothing.
    ///
    /// # Errors
    /// As [`idfoza`] for `q` and `x`; an `so` made for another model.
    pub fn idsoza<'a>(
        model: &MimicModel,
        data: &mut MimicData,
        so: &'a mut MimicSoData,
        q: &DVector<f64>,
        x: &DVector<f64>,
    ) -> Result<&'a Tensor3> {
        so.check(model)?;
        prepare(model, data, q, None, Some(("x", x)))?;
        model.expand_v_into(x.as_slice(), data.a.as_mut_slice());
        crate::deriv::zero::idsoza_ws(&model.full, &mut data.full, &mut so.full, &data.q, &data.a)?;
        model.reduce_tensor(so.full.d2tau_dq2(), &mut so.d2tau_dq2);
        Ok(&so.d2tau_dq2)
    }
}
