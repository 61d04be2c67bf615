//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with IDFOZA for the `∂M/∂q` products.

use super::id_fo::id_derivatives_placed;
use super::id_so::{SoData, id_so_unchecked};
use super::zero::{Idfoza4Ws, idfoza4_core};
use crate::algo::Data;
use crate::algo::internal::{
    DescView, DofDescendants, aba_unchecked, check_fext, ltl_in_place, ltl_solve_fd,
    ltl_solve_rows_head,
};
use crate::error::Result;
use crate::linalg::{gather_cols_to_rows, scatter_rows_to_cols, transpose_strided};
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

/// Right-hand-side columns solved side by side in one panel.
const P: usize = 32;

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
    /// IDFOZA results `S[(i, j, k)] = IDFOZA(X[:, j])[i][k]` at `i + n j + n² k`; only the
    /// structurally non-zero entries (the same for every `X`) are ever written.
    s: Vec<f64>,
    /// Panel of [`P`] right-hand sides stored by rows for the solve: `(i, l)` at `i P + l`.
    panel: Vec<f64>,
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
            s: vec![0.0; n * n * n],
            panel: vec![0.0; n * P],
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

/// How [`solve_neg_columns`] stores each solved column `(j, k)`.
#[derive(Clone, Copy, PartialEq)]
enum Store {
    /// Column `(j, k)` only.
    Plain,
    /// Also into column `(k, j)` when `mirror(j, k)` (a symmetry in `(j, k)`).
    Mirror,
    /// Column `(j, k)`, exact in rows `i ≤ j` only (the caller completes a symmetry in `(i, j)`).
    Head,
}

/// Solves `out[:, j, k] = −M⁻¹ b_jk` for the columns `(j, k)` of `pairs`, with `b_jk` the sum
/// of the first `nsrc` columns (`n`-vectors) returned by `src(j, k)`. Zero right-hand sides
/// give zero columns without a solve; the others go through the tree-sparse `LᵀDL` solve [`P`]
/// at a time in the L1-resident `panel` (gathered and stored by 4×4 transpositions).
#[allow(clippy::too_many_arguments)]
fn solve_neg_columns<'a>(
    model: &Model,
    ltl: &DMatrix<f64>,
    desc: DescView<'_>,
    panel: &mut [f64],
    out: &mut Tensor3,
    pairs: impl Iterator<Item = (usize, usize)>,
    nsrc: usize,
    src: impl Fn(usize, usize) -> [&'a [f64]; 3],
    store: Store,
    mirror: impl Fn(usize, usize) -> bool,
) {
    let n = model.nv;
    let out = out.as_mut_slice();
    assert!(out.len() == n * n * n && panel.len() == n * P && (1..=3).contains(&nsrc));
    // All writes to `out` below go through `base`.
    let base = out.as_mut_ptr();
    let mut srcs = [[std::ptr::null::<f64>(); 3]; P];
    let mut dsts = [[std::ptr::null_mut::<f64>(); 2]; P];
    let mut rows_end = 0;
    let mut w = 0;
    let mut flush =
        |w: usize, rows_end: usize, srcs: &[[*const f64; 3]], dsts: &[[*mut f64; 2]]| {
            // SAFETY: the source columns are n-long slices; the destinations are columns of `out`
            // (offsets n (j + n k) with j, k < n, so n values fit in n³).
            unsafe { gather_cols_to_rows(&srcs[..w], nsrc, n, panel, P) };
            let wp = w.next_multiple_of(4);
            ltl_solve_rows_head(model, ltl, desc, panel, P, wp, -1.0, rows_end);
            // SAFETY: as above.
            unsafe { scatter_rows_to_cols(panel, P, n, &dsts[..w]) };
        };
    for (j, k) in pairs {
        assert!(j < n && k < n);
        let s = src(j, k);
        assert!(s.iter().take(nsrc).all(|c| c.len() == n));
        let dst = [base.wrapping_add(n * (j + n * k)), base.wrapping_add(n * (k + n * j))];
        let dst = if store == Store::Mirror && mirror(j, k) { dst } else { [dst[0], dst[0]] };
        if s.iter().take(nsrc).all(|c| c.iter().all(|&x| x == 0.0)) {
            for p in dst {
                // SAFETY: a column of `out` (see `flush`).
                unsafe { std::ptr::write_bytes(p, 0, n) };
            }
            continue;
        }
        srcs[w] = [s[0].as_ptr(), s[1].as_ptr(), s[2].as_ptr()];
        dsts[w] = dst;
        rows_end = rows_end.max(if store == Store::Head { j + 1 } else { n });
        w += 1;
        if w == P {
            flush(w, rows_end, &srcs, &dsts);
            w = 0;
            rows_end = 0;
        }
    }
    if w > 0 {
        flush(w, rows_end, &srcs, &dsts);
    }
}

/// Fills the strict lower triangle of every page of the `n×n×n` tensor `t` from its upper one.
fn symmetrise_pages(n: usize, t: &mut [f64]) {
    assert!(t.len() == n * n * n);
    for page in t.chunks_exact_mut(n * n) {
        for j in 0..n {
            for i in j + 1..n {
                page[i + n * j] = page[j + n * i];
            }
        }
    }
}

/// `s[i + n j + n² k] ← IDFOZA(x[:, j])[i][k]` for the structurally non-zero `(i, k)`, four
/// right-hand sides at a time (vectorised with AVX2 when available).
fn idfoza_tensor(model: &Model, data: &Data, ws: &mut Idfoza4Ws, x: &[f64], s: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { return idfoza_tensor_avx2(model, data, ws, x, s) };
    }
    idfoza_tensor_impl(model, data, ws, x, s)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn idfoza_tensor_avx2(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    s: &mut [f64],
) {
    idfoza_tensor_impl(model, data, ws, x, s)
}

#[inline(always)]
fn idfoza_tensor_impl(model: &Model, data: &Data, ws: &mut Idfoza4Ws, x: &[f64], s: &mut [f64]) {
    let n = model.nv;
    let n2 = n * n;
    assert!(s.len() == n * n2 && x.len() == n2);
    let mut j0 = 0;
    while j0 < n {
        let nl = 4.min(n - j0);
        // SAFETY: i, k < n and j = j0 + l < n for l < nl, so every index is < n³ = s.len().
        idfoza4_core(model, data, ws, x, n, j0, nl, |i, k, z| unsafe {
            for (l, zl) in z.iter().enumerate().take(nl) {
                *s.get_unchecked_mut(i + n * (j0 + l) + n2 * k) = *zl;
            }
        });
        j0 += 4;
    }
}

/// Second-order derivatives of forward dynamics at `q̈ = FD(q, q̇, τ)` (eq. eqn_FD_SO_43):
/// `∂²q̈/∂u∂w = −M⁻¹(∂²ID/∂u∂w + ∂M/∂w · ∂FD/∂u + (∂M/∂u · ∂FD/∂w)^R)`, with the `∂M/∂q`
/// products by IDFOZA (`O(N d)` per column) instead of tensor products. Also fills the
/// first-order results in `data` (as [`fd_derivatives`]) and the ID second-order tensors in
/// `fso.id`.
///
/// Symmetries cut the solves: `∂²q̈/∂q̇²` is symmetric in `(j, k)`, and so is `∂²q̈/∂q²` for
/// DoFs of different joints (the configuration space is a product over joints); the pages of
/// `∂(M⁻¹)/∂q_k` are symmetric, so only their upper triangles are solved for.
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
    let s = &mut fso.s[..];
    assert!(s.len() == n * n * n);
    /// Column `(j, k)` of the `n×n×n` tensor `t`.
    fn col(t: &[f64], n: usize, j: usize, k: usize) -> &[f64] {
        &t[n * (j + n * k)..][..n]
    }
    let all = || (0..n).flat_map(move |k| (0..n).map(move |j| (j, k)));
    let dof_joint = &model.dof_joint;
    // DoFs of different joints commute (product of the joints' configuration spaces).
    let commute = |j: usize, k: usize| dof_joint[j] != dof_joint[k];
    let desc = fso.desc.view();
    // ∂²q̈/∂q²: −M⁻¹(ID_qq + A + A^R) with A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k] = S[i][j][k].
    idfoza_tensor(model, data, &mut fso.ws4, data.dqdd_dq.as_slice(), s);
    {
        let (idt, s) = (fso.id.d2tau_dq2().as_slice(), &*s);
        solve_neg_columns(
            model,
            &data.ltl,
            desc,
            &mut fso.panel,
            &mut fso.d2qdd_dq2,
            all().filter(|&(j, k)| j <= k || !commute(j, k)),
            3,
            |j, k| [col(idt, n, j, k), col(s, n, j, k), col(s, n, k, j)],
            Store::Mirror,
            commute,
        );
    }
    // ∂²q̈/∂q∂q̇: −M⁻¹(ID_qv + B) with B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j] = S[i][k][j].
    idfoza_tensor(model, data, &mut fso.ws4, data.dqdd_dv.as_slice(), s);
    {
        let (idt, s) = (fso.id.d2tau_dqdv().as_slice(), &*s);
        solve_neg_columns(
            model,
            &data.ltl,
            desc,
            &mut fso.panel,
            &mut fso.d2qdd_dqdv,
            all(),
            2,
            |j, k| [col(idt, n, j, k), col(s, n, k, j), col(s, n, k, j)],
            Store::Plain,
            commute,
        );
    }
    // ∂(M⁻¹)/∂q = −M⁻¹ C with C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k] = S[i][j][k]; rows i ≤ j,
    // by j so that each panel needs few rows.
    idfoza_tensor(model, data, &mut fso.ws4, data.minv.as_slice(), s);
    {
        let s = &*s;
        solve_neg_columns(
            model,
            &data.ltl,
            desc,
            &mut fso.panel,
            &mut fso.d2qdd_dtaudq,
            (0..n).flat_map(move |j| (0..n).map(move |k| (j, k))),
            1,
            |j, k| [col(s, n, j, k); 3],
            Store::Head,
            commute,
        );
        symmetrise_pages(n, fso.d2qdd_dtaudq.as_mut_slice());
    }
    // ∂²q̈/∂q̇²: −M⁻¹ ID_vv (M does not depend on q̇), symmetric in (j, k).
    {
        let idt = fso.id.d2tau_dv2().as_slice();
        solve_neg_columns(
            model,
            &data.ltl,
            desc,
            &mut fso.panel,
            &mut fso.d2qdd_dv2,
            all().filter(|&(j, k)| j <= k),
            1,
            |j, k| [col(idt, n, j, k); 3],
            Store::Mirror,
            |_, _| true,
        );
    }
    Ok(())
}
