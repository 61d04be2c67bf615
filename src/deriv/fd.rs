//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with IDFOZA for the `∂M/∂q` products.

use super::id_fo::id_derivatives_placed;
use super::id_so::{SoData, id_so_unchecked};
use super::zero::{Idfoza4Ws, idfoza4_core};
use crate::algo::Data;
use crate::algo::internal::{
    DescView, DofDescendants, aba_unchecked, check_fext, ltl_in_place, ltl_solve_fd,
    ltl_solve_rows_desc,
};
use crate::error::Result;
use crate::linalg::{transpose, transpose_strided};
use crate::model::{Model, check_vec};
use crate::spatial::Force;
use crate::tensor::Tensor3;
use nalgebra::{DMatrix, DVector};

/// FO FD part shared by first and second order: from `data.m`, `data.dtau_dq`, `data.dtau_dv`
/// (at `q̈ = FD`), factorise `M` and fill `dqdd_dq`, `dqdd_dv`, `minv`.
fn fd_fo_from_id(model: &Model, data: &mut Data) -> Result<()> {
    let n = model.nv;
    data.ltl.as_mut_slice().copy_from_slice(data.m.as_slice());
    ltl_in_place(model, &mut data.ltl)?;
    if n == 0 {
        return Ok(());
    }
    let ld = 3 * n;
    // One tree-sparse solve for the three right-hand sides, stored by rows:
    // ∂q̈/∂q = −M⁻¹ ∂τ/∂q, ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇, ∂q̈/∂τ = M⁻¹ (eq. jain_FO_eqn).
    let x = &mut data.fd_ws.x[..];
    assert!(x.len() == ld * n);
    transpose_strided(data.dtau_dq.as_slice(), n, n, n, x, ld);
    transpose_strided(data.dtau_dv.as_slice(), n, n, n, &mut x[n..], ld);
    for i in 0..n {
        let row = &mut x[i * ld + 2 * n + i..(i + 1) * ld];
        row.fill(0.0);
        row[0] = 1.0;
    }
    ltl_solve_fd(model, &data.ltl, &mut data.fd_ws);
    let x = &data.fd_ws.x[..];
    transpose_strided(x, ld, n, n, data.dqdd_dq.as_mut_slice(), n);
    transpose_strided(&x[n..], ld, n, n, data.dqdd_dv.as_mut_slice(), n);
    // M⁻¹ from its upper triangle (row i, columns k ≥ i of the identity part).
    let minv = data.minv.as_mut_slice();
    let xm = &x[2 * n..];
    assert!(minv.len() == n * n && xm.len() == ld * n - 2 * n);
    for c in 0..n {
        // SAFETY: r ≤ c < n, so r·ld + c < (n − 1)·ld + n = xm.len() and r + n·c < n².
        unsafe {
            for r in 0..c {
                *minv.get_unchecked_mut(r + n * c) = *xm.get_unchecked(r * ld + c);
            }
            for r in c..n {
                *minv.get_unchecked_mut(r + n * c) = *xm.get_unchecked(c * ld + r);
            }
        }
    }
    Ok(())
}

/// First-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)`:
/// `∂q̈/∂q = −M⁻¹ ∂τ/∂q`, `∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇`, `∂q̈/∂τ = M⁻¹` (eq. jain_FO_eqn), with IDSVA
/// at `(q, q̇, q̈)` and the tree-sparse `LᵀDL` factorisation of `M` (no dense inverse).
/// Fills `data.qdd`, `data.dqdd_dq`, `data.dqdd_dv`, `data.minv` (and the ID derivatives).
pub fn fd_derivatives(
    model: &Model,
    data: &mut Data,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    // ABA has just computed the placements at q.
    id_derivatives_placed(model, data, v, &qdd, fext);
    data.qdd = qdd;
    fd_fo_from_id(model, data)
}

/// Second-order forward-dynamics derivatives (`nv×nv×nv` each) and their workspace.
#[derive(Clone, Debug)]
pub struct FdSoData {
    /// The inverse-dynamics second-order derivatives at `(q, q̇, FD(q, q̇, τ))`.
    pub id: SoData,
    d2qdd_dq2: Tensor3,
    d2qdd_dv2: Tensor3,
    d2qdd_dqdv: Tensor3,
    d2qdd_dtaudq: Tensor3,
    ws4: Idfoza4Ws,
    /// Working tensor stored by rows of the solve: `(i, j, k)` at `j + n k + n² i`.
    tt: Vec<f64>,
    /// Descendant DoF lists for the pulling first sweep of the solves.
    desc: DofDescendants,
}

impl FdSoData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv;
        Self {
            id: SoData::new(model),
            d2qdd_dq2: Tensor3::zeros(n, n, n),
            d2qdd_dv2: Tensor3::zeros(n, n, n),
            d2qdd_dqdv: Tensor3::zeros(n, n, n),
            d2qdd_dtaudq: Tensor3::zeros(n, n, n),
            ws4: Idfoza4Ws::new(model),
            tt: vec![0.0; n * n * n],
            desc: DofDescendants::new(model),
        }
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dq2(&self) -> &Tensor3 {
        &self.d2qdd_dq2
    }
    /// `T[(i, j, k)] = ∂²q̈_i/∂q̇_j∂q̇_k`.
    pub fn d2qdd_dv2(&self) -> &Tensor3 {
        &self.d2qdd_dv2
    }
    /// `T[(i, j, k)] = ∂/∂q̇_k (∂q̈_i/∂q_j)`.
    pub fn d2qdd_dqdv(&self) -> &Tensor3 {
        &self.d2qdd_dqdv
    }
    /// `T[(i, j, k)] = ∂/∂q_k (∂q̈_i/∂τ_j) = ∂(M⁻¹)_ij/∂q_k`.
    pub fn d2qdd_dtaudq(&self) -> &Tensor3 {
        &self.d2qdd_dtaudq
    }
}

/// `out ← −M⁻¹ T` for the tensor `T` held in `tt` by rows (`(i, j, k)` at `j + n k + n² i`):
/// tree-sparse multi-right-hand-side solves on blocks of `(j, k)` columns (cache-sized), then
/// one transposition into the column-major `out`.
fn solve_neg_tensor(
    model: &Model,
    ltl: &DMatrix<f64>,
    desc: DescView<'_>,
    tt: &mut [f64],
    out: &mut Tensor3,
) {
    const W: usize = 64;
    let n = model.nv;
    let n2 = n * n;
    let mut b = 0;
    while b < n2 {
        let w = W.min(n2 - b);
        ltl_solve_rows_desc(model, ltl, desc, &mut tt[b..], n2, w, -1.0);
        b += w;
    }
    transpose(tt, n2, n, out.as_mut_slice());
}

/// Which IDFOZA term of eq. eqn_FD_SO_43 [`add_idfoza_terms`] adds.
#[derive(Clone, Copy, PartialEq)]
enum Term {
    /// `A + A^R`, `A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k]`.
    Dq2,
    /// `B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j]`.
    Dqdv,
    /// `C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k]` (written, not added).
    Minv,
}

/// Adds one IDFOZA term to `tt` (stored by rows, `(i, j, k)` at `j + n k + n² i`), four
/// right-hand sides at a time (vectorised with AVX2 when available).
fn add_idfoza_terms(model: &Model, data: &Data, ws: &mut Idfoza4Ws, tt: &mut [f64], term: Term) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { return add_idfoza_terms_avx2(model, data, ws, tt, term) };
    }
    add_idfoza_terms_impl(model, data, ws, tt, term)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn add_idfoza_terms_avx2(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    tt: &mut [f64],
    term: Term,
) {
    add_idfoza_terms_impl(model, data, ws, tt, term)
}

#[inline(always)]
fn add_idfoza_terms_impl(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    tt: &mut [f64],
    term: Term,
) {
    let n = model.nv;
    let n2 = n * n;
    assert!(tt.len() == n * n2);
    let x = match term {
        Term::Dq2 => data.dqdd_dq.as_slice(),
        Term::Dqdv => data.dqdd_dv.as_slice(),
        Term::Minv => data.minv.as_slice(),
    };
    let mut j0 = 0;
    while j0 < n {
        let nl = 4.min(n - j0);
        // SAFETY (the `put` closures): i, k < n and j = j0 + l < n for l < nl, so every index
        // is < n³ = tt.len().
        match term {
            Term::Dq2 => idfoza4_core(model, data, ws, x, n, j0, nl, |i, k, z| unsafe {
                for (l, zl) in z.iter().enumerate().take(nl) {
                    let j = j0 + l;
                    *tt.get_unchecked_mut(j + n * k + n2 * i) += zl;
                    *tt.get_unchecked_mut(k + n * j + n2 * i) += zl;
                }
            }),
            Term::Dqdv => idfoza4_core(model, data, ws, x, n, j0, nl, |i, j, z| unsafe {
                for (l, zl) in z.iter().enumerate().take(nl) {
                    *tt.get_unchecked_mut(j + n * (j0 + l) + n2 * i) += zl;
                }
            }),
            Term::Minv => idfoza4_core(model, data, ws, x, n, j0, nl, |i, k, z| unsafe {
                for (l, zl) in z.iter().enumerate().take(nl) {
                    *tt.get_unchecked_mut(j0 + l + n * k + n2 * i) = *zl;
                }
            }),
        }
        j0 += 4;
    }
}

/// Second-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)` (eq. eqn_FD_SO_43):
/// `∂²q̈/∂u∂w = −M⁻¹(∂²ID/∂u∂w + ∂M/∂w · ∂FD/∂u + (∂M/∂u · ∂FD/∂w)^R)`, with the `∂M/∂q`
/// products by IDFOZA (`O(N d)` per column) instead of tensor products. Also fills the
/// first-order results in `data` (as [`fd_derivatives`]) and the ID second-order tensors in
/// `fso.id`.
pub fn fd_so_derivatives(
    model: &Model,
    data: &mut Data,
    fso: &mut FdSoData,
    q: &DVector<f64>,
    v: &DVector<f64>,
    tau: &DVector<f64>,
    fext: Option<&[Force]>,
) -> Result<()> {
    model.check_q(q)?;
    data.check(model)?;
    check_vec("v", v, model.nv)?;
    check_vec("tau", tau, model.nv)?;
    check_fext(model, fext)?;
    fso.id.check(model)?;
    if fso.d2qdd_dq2.dims() != (model.nv, model.nv, model.nv) {
        return Err(crate::error::Error::Dimension {
            what: "FdSoData (built for another model): nv".into(),
            expected: model.nv,
            got: fso.d2qdd_dq2.dims().0,
        });
    }
    let n = model.nv;
    aba_unchecked(model, data, q, v, tau, fext)?;
    let qdd = std::mem::replace(&mut data.qdd, DVector::zeros(0));
    id_so_unchecked(model, data, &mut fso.id, q, v, &qdd, fext, -model.gravity);
    data.qdd = qdd;
    fd_fo_from_id(model, data)?;
    let n2 = n * n;
    let tt = &mut fso.tt[..];
    assert!(tt.len() == n * n2);
    // ∂²q̈/∂q²: ID_qq + A + A^R with A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k].
    transpose(fso.id.d2tau_dq2().as_slice(), n, n2, tt);
    add_idfoza_terms(model, data, &mut fso.ws4, tt, Term::Dq2);
    solve_neg_tensor(model, &data.ltl, fso.desc.view(), tt, &mut fso.d2qdd_dq2);
    // ∂²q̈/∂q∂q̇: ID_qv + B with B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j] (page k).
    transpose(fso.id.d2tau_dqdv().as_slice(), n, n2, tt);
    add_idfoza_terms(model, data, &mut fso.ws4, tt, Term::Dqdv);
    solve_neg_tensor(model, &data.ltl, fso.desc.view(), tt, &mut fso.d2qdd_dqdv);
    // ∂(M⁻¹)/∂q = −M⁻¹ C with C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k].
    tt.fill(0.0);
    add_idfoza_terms(model, data, &mut fso.ws4, tt, Term::Minv);
    solve_neg_tensor(model, &data.ltl, fso.desc.view(), tt, &mut fso.d2qdd_dtaudq);
    // ∂²q̈/∂q̇²: ID_vv (M does not depend on q̇).
    transpose(fso.id.d2tau_dv2().as_slice(), n, n2, tt);
    solve_neg_tensor(model, &data.ltl, fso.desc.view(), tt, &mut fso.d2qdd_dv2);
    Ok(())
}
