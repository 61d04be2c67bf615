//! Forward-dynamics derivatives: first order (`∂q̈/∂u = −M⁻¹ ∂ID/∂u`, eq. jain_FO_eqn) and
//! second order (eq. eqn_FD_SO_43), the latter with IDFOZA for the `∂M/∂q` products.

use super::id_fo::id_derivatives_placed;
use super::id_so::{SoData, id_so_unchecked};
#[cfg(target_arch = "x86_64")]
use super::zero::Avx4;
use super::zero::{Idfoza4Ws, Lane4, idfoza4_core};
use crate::algo::Data;
use crate::algo::internal::{
    DescView, DofDescendants, aba_unchecked, check_fext, ltl_in_place, ltl_solve_fd,
    ltl_solve_rows_head,
};
use crate::error::Result;
use crate::linalg::{LaneSrc, gather_group, prefetch_l2, scatter_rows_to_cols, transpose_strided};
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
    // Small models: the columns of ∂τ/∂q, ∂τ/∂q̇ and of the identity solved one by one in the
    // native (column-major) layout; the row-stored multi-right-hand-side solve below costs more
    // in its transpositions and set-up than it saves when nv is this small.
    const SMALL_NV: usize = 3;
    if n <= SMALL_NV {
        // ∂q̈/∂q = −M⁻¹ ∂τ/∂q, ∂q̈/∂q̇ = −M⁻¹ ∂τ/∂q̇, ∂q̈/∂τ = M⁻¹ (eq. jain_FO_eqn).
        for (o, s) in data.dqdd_dq.as_mut_slice().iter_mut().zip(data.dtau_dq.as_slice()) {
            *o = -s;
        }
        for (o, s) in data.dqdd_dv.as_mut_slice().iter_mut().zip(data.dtau_dv.as_slice()) {
            *o = -s;
        }
        data.minv.fill_with_identity();
        let h = data.ltl.as_slice();
        let mut mats =
            [data.dqdd_dq.as_mut_slice(), data.dqdd_dv.as_mut_slice(), data.minv.as_mut_slice()];
        assert!(h.len() == n * n && mats.iter().all(|m| m.len() == n * n));
        // SAFETY (the unchecked accesses below): i, c < n and the ancestor DoFs j < i come from
        // `Model::dof_ancestors`, so every index is < n² = the length of `h` and of each matrix.
        // Lᵀ y = b (L(k, i) at (i, k) of the factor), every column at once.
        for i in (0..n).rev() {
            for &j in model.ancestors_of_dof(i) {
                // SAFETY: j < i < n (see above).
                let l = unsafe { *h.get_unchecked(j + n * i) };
                for m in mats.iter_mut() {
                    for c in 0..n {
                        // SAFETY: i, j, c < n (see above).
                        unsafe {
                            let xi = *m.get_unchecked(i + n * c);
                            *m.get_unchecked_mut(j + n * c) -= l * xi;
                        }
                    }
                }
            }
        }
        // x = L⁻¹ D⁻¹ y.
        for i in 0..n {
            let anc = model.ancestors_of_dof(i);
            // SAFETY: i < n (see above).
            let dinv = 1.0 / unsafe { *h.get_unchecked(i + n * i) };
            for m in mats.iter_mut() {
                for c in 0..n {
                    // SAFETY: i, c < n and the ancestors j < i (see above).
                    unsafe {
                        let mut acc = *m.get_unchecked(i + n * c) * dinv;
                        for &j in anc {
                            acc -= *h.get_unchecked(j + n * i) * *m.get_unchecked(j + n * c);
                        }
                        *m.get_unchecked_mut(i + n * c) = acc;
                    }
                }
            }
        }
        // M⁻¹ exactly symmetric: the strict lower triangle from the upper one.
        let minv = &mut mats[2];
        for c in 0..n {
            for r in c + 1..n {
                minv[r + n * c] = minv[c + n * r];
            }
        }
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
const P: usize = 64;

/// Second-order forward-dynamics derivatives (`nv×nv×nv` each) and their workspace.
#[derive(Clone, Debug)]
pub struct FdSoData {
    /// The inverse-dynamics second-order derivatives at `(q, q̇, FD(q, q̇, τ))` (the three
    /// `∂²τ` tensors; its `dm_dq` is empty, the `∂M/∂q` products being done by IDFOZA).
    pub id: SoData,
    d2qdd_dq2: Tensor3,
    d2qdd_dv2: Tensor3,
    d2qdd_dqdv: Tensor3,
    d2qdd_dtaudq: Tensor3,
    ws4: Idfoza4Ws,
    /// IDFOZA results `S[(i, j, k)] = IDFOZA(X[:, j])[i][k]` at `i + n j + n² k`; only the
    /// structurally non-zero entries (the same for every `X`) are ever written.
    s: Vec<f64>,
    /// IDFOZA of four right-hand sides `X[:, j0..j0 + 4]`: `(u, i, k)` at `u + 4 i + 4 n k`.
    s4: Vec<f64>,
    /// Panel of [`P`] right-hand sides stored by rows for the solve: `(i, l)` at `i P + l`.
    panel: Vec<f64>,
    /// One `n×n` page (transposition scratch).
    page: Vec<f64>,
    /// Descendant DoF lists for the pulling first sweep of the solves.
    desc: DofDescendants,
    /// `related[j + n k]`: DoFs `j` and `k` are equal or one is an ancestor of the other (else
    /// the column `(j, k)` of `∂²q̈/∂q̇²` is structurally zero and never written; `id.check`
    /// keeps the workspace to the tree it was built for).
    related: Vec<bool>,
}

impl FdSoData {
    /// Workspace for `model`.
    pub fn new(model: &Model) -> Self {
        let n = model.nv;
        Self {
            id: SoData::without_dm_dq(model),
            d2qdd_dq2: Tensor3::zeros(n, n, n),
            d2qdd_dv2: Tensor3::zeros(n, n, n),
            d2qdd_dqdv: Tensor3::zeros(n, n, n),
            d2qdd_dtaudq: Tensor3::zeros(n, n, n),
            ws4: Idfoza4Ws::new(model),
            s: vec![0.0; n * n * n],
            s4: vec![0.0; 4 * n * n],
            panel: vec![0.0; n * P],
            page: vec![0.0; n * n],
            desc: DofDescendants::new(model),
            related: (0..n * n)
                .map(|c| {
                    let (j, k) = (c % n, c / n);
                    j == k
                        || model.ancestors_of_dof(k).contains(&j)
                        || model.ancestors_of_dof(j).contains(&k)
                })
                .collect(),
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

/// How [`solve_neg_groups`] stores each solved column `(j, k)`.
#[derive(Clone, Copy, PartialEq)]
enum Store {
    /// Column `(j, k)` only.
    Plain,
    /// Column `(j, k)`, and also column `(k, j)` when `j < k` and `mirror(j, k)` (a symmetry
    /// in `(j, k)`).
    Mirror,
    /// Column `(j, k)`, exact in rows `i ≤ j` only (the caller completes a symmetry in `(i, j)`);
    /// rows past the panel's last solved row are left as they were.
    Head,
}

/// A group of up to 4 right-hand-side columns: `(j + u, k)` (`by_j`) or `(j, k + u)`, `u < w`.
#[derive(Clone, Copy)]
struct Group {
    j: usize,
    k: usize,
    w: usize,
    by_j: bool,
}

impl Group {
    fn lane(&self, u: usize) -> (usize, usize) {
        if self.by_j { (self.j + u, self.k) } else { (self.j, self.k + u) }
    }
}

/// Solves `out[:, j, k] = −M⁻¹ b_jk` for the columns of `groups`, with `b_jk` the sum of the
/// terms `src(group)` (see [`LaneSrc`]). All-zero groups give zero columns without a solve;
/// the others go through the tree-sparse `LᵀDL` solve [`P`] columns at a time in the
/// L1-resident `panel` (gathered and stored by 4×4 transpositions).
///
/// # Safety
/// Every term returned by `src(g)` addresses readable values for the lanes `u < g.w`, rows
/// `i < n`.
#[allow(clippy::too_many_arguments)]
unsafe fn solve_neg_groups(
    model: &Model,
    ltl: &DMatrix<f64>,
    desc: DescView<'_>,
    panel: &mut [f64],
    out: &mut Tensor3,
    groups: impl Iterator<Item = Group>,
    src: impl Fn(&Group) -> ([LaneSrc; 3], usize),
    store: Store,
    mirror: impl Fn(usize, usize) -> bool,
) {
    let n = model.nv;
    let out = out.as_mut_slice();
    assert!(out.len() == n * n * n && panel.len() == n * P);
    // All writes to `out` below go through `base`.
    let base = out.as_mut_ptr();
    let mut dsts = [[std::ptr::null_mut::<f64>(); 2]; P];
    let mut rows_end = 0;
    let mut l0 = 0;
    let flush = |panel: &mut [f64], l0: usize, rows_end: usize, dsts: &[[*mut f64; 2]]| {
        ltl_solve_rows_head(model, ltl, desc, panel, P, l0, -1.0, rows_end);
        // Rows past `rows_end` were not solved (`Store::Head`): not stored either.
        // SAFETY: every non-null destination is a column of `out` (offset n (j + n k) with
        // j, k < n, so n ≥ rows_end values fit in n³).
        unsafe { scatter_rows_to_cols(panel, P, rows_end, &dsts[..l0]) };
    };
    for g in groups {
        assert!(g.w <= 4 && g.lane(g.w - 1).0 < n && g.lane(g.w - 1).1 < n);
        let (terms, nt) = src(&g);
        // SAFETY: the caller's contract on `src`; l0 + 4 ≤ P.
        let nz = unsafe { gather_group(&terms[..nt], g.w, n, panel, P, l0) };
        for u in 0..4 {
            let d = &mut dsts[l0 + u];
            *d = [std::ptr::null_mut(); 2];
            if u < g.w {
                let (j, k) = g.lane(u);
                d[0] = base.wrapping_add(n * (j + n * k));
                d[1] = if store == Store::Mirror && j < k && mirror(j, k) {
                    base.wrapping_add(n * (k + n * j))
                } else {
                    d[0]
                };
            }
        }
        if !nz {
            for d in &dsts[l0..l0 + g.w] {
                for &p in d {
                    // SAFETY: a column of `out` (see `flush`).
                    unsafe { std::ptr::write_bytes(p, 0, n) };
                }
            }
            continue;
        }
        let rows = if store == Store::Head {
            rows_end = rows_end.max(g.lane(g.w - 1).0 + 1);
            g.lane(g.w - 1).0 + 1
        } else {
            rows_end = n;
            n
        };
        // The destination columns into L2 while the panel fills and is solved.
        for d in &dsts[l0..l0 + g.w] {
            prefetch_l2(d[0], rows);
            if d[1] != d[0] {
                prefetch_l2(d[1], rows);
            }
        }
        l0 += 4;
        if l0 == P {
            flush(panel, l0, rows_end, &dsts);
            l0 = 0;
            rows_end = 0;
        }
    }
    if l0 > 0 {
        flush(panel, l0, rows_end, &dsts);
    }
}

/// Fills the strict lower triangle of every page of the `n×n×n` tensor `t` from its upper one,
/// through the transposed page in `tmp` (`n²` values).
fn symmetrise_pages(n: usize, t: &mut [f64], tmp: &mut [f64]) {
    assert!(t.len() == n * n * n && tmp.len() == n * n);
    for page in t.chunks_exact_mut(n * n) {
        transpose_strided(page, n, n, n, tmp, n);
        for j in 0..n {
            let c = n * j;
            page[c + j + 1..c + n].copy_from_slice(&tmp[c + j + 1..c + n]);
        }
    }
}

/// `s[j + n i + n² k] ← IDFOZA(x[:, j])[i][k]` for the structurally non-zero `(i, k)`, four
/// right-hand sides at a time (vectorised with AVX2 when available).
fn idfoza_tensor(model: &Model, data: &Data, ws: &mut Idfoza4Ws, x: &[f64], s: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { return idfoza_tensor_avx2(model, data, ws, x, s) };
    }
    idfoza_tensor_impl::<[f64; 4]>(model, data, ws, x, s)
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
    // SAFETY: AVX2 and FMA are enabled here, as `Avx4` needs.
    idfoza_tensor_impl::<Avx4>(model, data, ws, x, s)
}

#[inline(always)]
fn idfoza_tensor_impl<V: Lane4>(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    s: &mut [f64],
) {
    let n = model.nv;
    let n2 = n * n;
    assert!(s.len() == n * n2 && x.len() == n2);
    let mut j0 = 0;
    while j0 < n {
        let nl = 4.min(n - j0);
        // SAFETY: i, k < n and j = j0 + l < n for l < nl, so every index is < n³ = s.len().
        if nl == 4 {
            // Full groups: the four lanes are contiguous.
            idfoza4_core::<V>(model, data, ws, x, n, j0, 4, |i, k, z| unsafe {
                *s.as_mut_ptr().add(j0 + n * i + n2 * k).cast::<[f64; 4]>() = *z;
            });
        } else {
            idfoza4_core::<V>(model, data, ws, x, n, j0, nl, |i, k, z| unsafe {
                for (l, zl) in z.iter().enumerate().take(nl) {
                    *s.get_unchecked_mut(j0 + l + n * i + n2 * k) = *zl;
                }
            });
        }
        j0 += 4;
    }
}

/// `out[u + 4 i + 4 n k] ← IDFOZA(x[:, j0 + u])[i][k]` for the structurally non-zero `(i, k)`
/// (zero in the lanes past `nv`), vectorised with AVX2 when available.
fn idfoza_block(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    j0: usize,
    out: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    if crate::simd::avx2_fma() {
        // SAFETY: the CPU supports the enabled features.
        unsafe { return idfoza_block_avx2(model, data, ws, x, j0, out) };
    }
    idfoza_block_impl::<[f64; 4]>(model, data, ws, x, j0, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn idfoza_block_avx2(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    j0: usize,
    out: &mut [f64],
) {
    // SAFETY: AVX2 and FMA are enabled here, as `Avx4` needs.
    idfoza_block_impl::<Avx4>(model, data, ws, x, j0, out)
}

#[inline(always)]
fn idfoza_block_impl<V: Lane4>(
    model: &Model,
    data: &Data,
    ws: &mut Idfoza4Ws,
    x: &[f64],
    j0: usize,
    out: &mut [f64],
) {
    let n = model.nv;
    assert!(out.len() == 4 * n * n && j0 < n && x.len() == n * n);
    // Lanes past nv read no column and come out zero.
    idfoza4_core::<V>(model, data, ws, x, n, j0, 4.min(n - j0), |i, k, z| {
        debug_assert!(i < n && k < n);
        // SAFETY: i, k < n, so 4 i + 4 n k + 3 < 4 n² = out.len().
        unsafe { *out.as_mut_ptr().add(4 * i + 4 * n * k).cast::<[f64; 4]>() = *z };
    });
}

/// The groups of the `n²` columns that use `IDFOZA(x[:, c0..c0 + 4])`, by `c0` (step 4): for
/// each `c0`, the block `s4 ← IDFOZA(x[:, c0..c0 + 4])` (see [`idfoza_block`]) is computed when
/// the iterator reaches it, then its `n` groups follow: `(c0.., m)` if `BY_J`, else `(m, c0..)`,
/// for `m < n`. The caller gathers each group before asking for the next (as
/// [`solve_neg_groups`] does), reading the block through `s4`.
///
/// # Safety
/// `s4` is valid for reads and writes of `4 n²` values for `'a`, and no reference into them is
/// alive while the iterator advances.
unsafe fn blocked_groups<'a, const BY_J: bool>(
    model: &'a Model,
    data: &'a Data,
    ws4: &'a mut Idfoza4Ws,
    x: &'a [f64],
    s4: *mut f64,
) -> impl Iterator<Item = Group> + 'a {
    let n = model.nv;
    (0..n).step_by(4).flat_map(move |c0| {
        // SAFETY: the function's contract.
        idfoza_block(model, data, ws4, x, c0, unsafe {
            std::slice::from_raw_parts_mut(s4, 4 * n * n)
        });
        let w = 4.min(n - c0);
        (0..n).map(move |m| {
            if BY_J {
                Group { j: c0, k: m, w, by_j: true }
            } else {
                Group { j: m, k: c0, w, by_j: false }
            }
        })
    })
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
    let n2 = n * n;
    let dof_joint = &model.dof_joint;
    // DoFs of different joints commute (product of the joints' configuration spaces).
    let commute = |j: usize, k: usize| dof_joint[j] != dof_joint[k];
    let desc = fso.desc.view();
    /// Lane u's pointer `f(j_u, k_u)` (lanes past the group repeat its last one).
    #[inline(always)]
    fn lanes(g: &Group, f: impl Fn(usize, usize) -> *const f64) -> [*const f64; 4] {
        let l = |u: usize| {
            let (j, k) = g.lane(u.min(g.w - 1));
            f(j, k)
        };
        [l(0), l(1), l(2), l(3)]
    }
    // Groups (j0.., k) of page k for j0 < jend(k), by 4.
    fn pages(n: usize, jend: &dyn Fn(usize) -> usize) -> impl Iterator<Item = Group> + '_ {
        (0..n).flat_map(move |k| {
            (0..jend(k)).step_by(4).map(move |j| Group { j, k, w: 4.min(n - j), by_j: true })
        })
    }
    // ∂²q̈/∂q²: −M⁻¹(ID_qq + A + A^R) with A[i][j][k] = IDFOZA(∂q̈/∂q[:, j])[i][k], held in
    // S at j + n i + n² k. Columns j ≤ k (and the non-commuting j > k of k's joint).
    idfoza_tensor(model, data, &mut fso.ws4, data.dqdd_dq.as_slice(), s);
    {
        let (idt, sp) = (fso.id.d2tau_dq2().as_slice().as_ptr(), s.as_ptr());
        let jend = |k: usize| {
            let jt = dof_joint[k];
            (k + 1).max(model.idx_v[jt] + model.nvs[jt])
        };
        // SAFETY (pointers): lanes have j, k < n, so the columns of ID_qq (n (j + n k) + i)
        // and the entries of S (j + n i + n² k, k + n i + n² j) for i < n are in the n³ tensors.
        unsafe {
            solve_neg_groups(
                model,
                &data.ltl,
                desc,
                &mut fso.panel,
                &mut fso.d2qdd_dq2,
                pages(n, &jend),
                |g| {
                    let id = lanes(g, |j, k| idt.wrapping_add(n * (j + n * k)));
                    let ar = lanes(g, |j, k| sp.wrapping_add(k + n2 * j));
                    let a = LaneSrc::Rows(sp.wrapping_add(g.j + n2 * g.k), n);
                    ([LaneSrc::Cols(id), a, LaneSrc::Strided(ar, n)], 3)
                },
                Store::Mirror,
                commute,
            )
        };
    }
    // ∂²q̈/∂q∂q̇: −M⁻¹(ID_qv + B) with B[i][j][k] = IDFOZA(∂q̈/∂q̇[:, k])[i][j]; groups
    // (j, k0..k0 + 4) for every j, by k0: IDFOZA of the four columns k0.. is computed into the
    // cache-resident block `s4` (at u + 4 i + 4 n j) just before their groups are gathered.
    {
        let idt = fso.id.d2tau_dqdv().as_slice().as_ptr();
        assert!(fso.s4.len() == 4 * n2);
        let s4 = fso.s4.as_mut_ptr();
        // SAFETY: `s4` is `fso.s4` (4 n² values, asserted), only accessed through this pointer
        // (writes by the iterator, reads by the gathers) until the solve returns.
        let groups = unsafe {
            blocked_groups::<false>(model, data, &mut fso.ws4, data.dqdd_dv.as_slice(), s4)
        };
        let s4 = s4.cast_const();
        // SAFETY (pointers): lanes have j, k < n, so the columns of ID_qv (n (j + n k) + i) are
        // in the n³ tensor and the block entries (u + 4 i + 4 n j, u < 4, i < n) in 4 n².
        unsafe {
            solve_neg_groups(
                model,
                &data.ltl,
                desc,
                &mut fso.panel,
                &mut fso.d2qdd_dqdv,
                groups,
                |g| {
                    let id = lanes(g, |j, k| idt.wrapping_add(n * (j + n * k)));
                    let b = LaneSrc::Rows(s4.wrapping_add(4 * n * g.j), 4);
                    ([LaneSrc::Cols(id), b, b], 2)
                },
                Store::Plain,
                |_, _| false,
            )
        };
    }
    // ∂(M⁻¹)/∂q = −M⁻¹ C with C[i][j][k] = IDFOZA(M⁻¹[:, j])[i][k]; rows i ≤ j, by j0 so that
    // each panel needs few rows; IDFOZA of the columns j0..j0 + 4 into `s4` (at u + 4 i + 4 n k)
    // just before their groups are gathered.
    {
        assert!(fso.s4.len() == 4 * n2);
        let s4 = fso.s4.as_mut_ptr();
        // SAFETY: `s4` is `fso.s4` (4 n² values, asserted), only accessed through this pointer
        // (writes by the iterator, reads by the gathers) until the solve returns.
        let groups =
            unsafe { blocked_groups::<true>(model, data, &mut fso.ws4, data.minv.as_slice(), s4) };
        let s4 = s4.cast_const();
        // SAFETY (pointers): block entries u + 4 i + 4 n k with u < 4, i, k < n are in 4 n².
        unsafe {
            solve_neg_groups(
                model,
                &data.ltl,
                desc,
                &mut fso.panel,
                &mut fso.d2qdd_dtaudq,
                groups,
                |g| {
                    let c = LaneSrc::Rows(s4.wrapping_add(4 * n * g.k), 4);
                    ([c, c, c], 1)
                },
                Store::Head,
                commute,
            )
        };
        symmetrise_pages(n, fso.d2qdd_dtaudq.as_mut_slice(), &mut fso.page);
    }
    // ∂²q̈/∂q̇²: −M⁻¹ ID_vv (M does not depend on q̇), symmetric in (j, k). Its column (j, k)
    // vanishes unless j = k or one DoF is an ancestor of the other (every velocity product in a
    // body's bias force is of two of its ancestors): groups without such a column are skipped.
    {
        let idt = fso.id.d2tau_dv2().as_slice().as_ptr();
        let related = &fso.related;
        let groups = pages(n, &|k| k + 1).filter(|g| (0..g.w).any(|u| related[g.j + u + n * g.k]));
        // SAFETY (pointers): as for ∂²q̈/∂q².
        unsafe {
            solve_neg_groups(
                model,
                &data.ltl,
                desc,
                &mut fso.panel,
                &mut fso.d2qdd_dv2,
                groups,
                |g| {
                    let id = LaneSrc::Cols(lanes(g, |j, k| idt.wrapping_add(n * (j + n * k))));
                    ([id, id, id], 1)
                },
                Store::Mirror,
                |_, _| true,
            )
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::random_tree;
    use crate::rng::Rng;

    /// A workspace made for a model with the same `nv` but another tree is refused, and the
    /// caller's data is left as it was.
    #[test]
    fn fd_so_workspace_of_another_tree_is_refused() {
        let a = random_tree(5, 1, false);
        let b = (2..200)
            .map(|s| random_tree(5, s, false))
            .find(|b| b.nv == a.nv && b.dof_ancestors != a.dof_ancestors)
            .expect("a tree with the same nv and another structure");
        let mut rng = Rng::new(3);
        let q = a.random_configuration(&mut rng);
        let v = DVector::from_fn(a.nv, |_, _| rng.range(-1.0, 1.0));
        let mut d = Data::new(&a);
        let mut fso = FdSoData::new(&b);
        let e = fd_so_derivatives(&a, &mut d, &mut fso, &q, &v, &v, None).unwrap_err();
        let e = e.to_string();
        assert!(e.contains("another model") && e.contains("different joint tree"), "{e}");
        assert!(fso.d2qdd_dv2().as_slice().iter().all(|x| *x == 0.0));
        let mut fso = FdSoData::new(&a);
        fd_so_derivatives(&a, &mut d, &mut fso, &q, &v, &v, None).unwrap();
    }
}
