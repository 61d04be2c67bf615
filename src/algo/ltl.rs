//! Tree-sparse `LᵀDL` factorisation of the mass matrix (Featherstone, RBDA §6.5) and solves.
//!
//! The factor is kept in the **upper** triangle of a column-major `nv×nv` matrix: `L(k, i)`
//! (`i` a strict ancestor DoF of `k`) is stored at `(i, k)`, `D(k)` at `(k, k)`, so each step
//! walks one contiguous column.
//!
//! [`factorize_ltl`]: inputs `M` (`data.m`, from [`super::crba()`]); output the factor
//! `M = Lᵀ D L` in `data.ltl` (`L` unit lower triangular with the sparsity of the tree:
//! `L(k, i) ≠ 0` only for ancestor DoFs `i` of `k`). With `H = M` and `anc(k)` the strict
//! ancestor DoFs of `k`, nearest first:
//! 1. for `k = nv − 1` down to `0`: the pivot `d_k = H(k, k)` (not positive and finite: an
//!    error); for each `i ∈ anc(k)`: `a = H(i, k) / d_k`, `H(i, i) −= a H(i, k)`,
//!    `H(j, i) −= a H(j, k)` for the `j ∈ anc(i)` (the tail of `anc(k)` after `i`), then
//!    `L(k, i) = a` (stored in place of `H(i, k)`);
//! 2. the relative test `min_k d_k ≤ 1e-14 · max_k d_k` (see [`factorize_ltl`]).
//!
//! [`solve_ltl`] (`M x = b`, in place): inputs the factor and `b`; output `x`:
//! 1. `Lᵀ y = b`: for `i = nv − 1` down to `0`, `y_j −= L(i, j) y_i` for `j ∈ anc(i)`;
//! 2. `z = D⁻¹ y`;
//! 3. `L x = z`: for `i = 0..nv`, `x_i = z_i − Σ_{j ∈ anc(i)} L(i, j) x_j`.
//!
//! Cost `O(nv d)` per solve, `O(nv d²)` for the factorisation (`d` the depth of the tree in
//! DoFs). [`solve_ltl_matrix`] solves column by column.

use super::Data;
use crate::error::{Error, Result};
use crate::model::{Model, check_vec};
use crate::simd::F64x4;
use nalgebra::{DMatrix, DVector};
use std::mem::MaybeUninit;

/// Factorises `data.m` (from [`super::crba()`]) as `M = Lᵀ D L` into `data.ltl`, exploiting the
/// branch-induced sparsity: cost `O(n d²)` for a tree of depth `d`.
///
/// # Singular mass matrices
/// The pivots `d_k` (the diagonal of `D`, eliminated from the last DoF to the first) are tested
/// as in [`super::aba()`], whose articulated inertias `D_i = S_iᵀ I^A_i S_i` have the same pivots
/// in exact arithmetic: `M` is reported singular ([`Error::Singular`], naming the pivot, its
/// velocity index and its joint) when a pivot is not positive and finite, or when the smallest
/// pivot is at most `1e-14` times the largest one (`min_k d_k ≤ 1e-14 · max_k d_k`), e.g. for a
/// massless leaf body or a massless link between two joints whose motions then coincide.
pub fn factorize_ltl(model: &Model, data: &mut Data) -> Result<()> {
    data.check_tree(model)?;
    data.ltl.copy_from(&data.m);
    ltl_in_place(model, &mut data.ltl)
}

/// Relative tolerance of the singularity test on the pivots of `M = Lᵀ D L`, shared by
/// [`factorize_ltl`] (and every algorithm that factorises `M`) and [`super::aba()`]: `M` is
/// singular when `min_k d_k ≤ PIVOT_RTOL · max_k d_k` (see [`Pivots`]).
pub(crate) const PIVOT_RTOL: f64 = 1e-14;

/// `true` if the pivot `d` can be inverted and the factorisation go on: `0 < d < ∞` (not NaN).
#[inline(always)]
pub(crate) fn pivot_ok(d: f64) -> bool {
    d > 0.0 && d < f64::INFINITY
}

/// The smallest and largest pivots of one factorisation of `M`, for the relative test that
/// [`ltl_in_place`] and ABA share: each pivot is first checked by [`pivot_ok`] (a failure is an
/// error at once, [`pivot_error`]), then [`Pivots::record`]ed; [`Pivots::finish`] applies
/// `min_k d_k ≤ PIVOT_RTOL · max_k d_k` once all are known.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pivots {
    min: f64,
    min_dof: usize,
    max: f64,
}

impl Pivots {
    /// No pivot yet (an empty factorisation passes).
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Self { min: f64::INFINITY, min_dof: 0, max: 0.0 }
    }
    /// Records the pivot `d` (already checked by [`pivot_ok`]) of velocity index `k`.
    #[inline(always)]
    pub(crate) fn record(&mut self, k: usize, d: f64) {
        if d < self.min {
            self.min = d;
            self.min_dof = k;
        }
        if d > self.max {
            self.max = d;
        }
    }
    /// The relative test: an error naming the smallest pivot's DoF and joint if
    /// `min_k d_k ≤ PIVOT_RTOL · max_k d_k`.
    #[inline]
    pub(crate) fn finish(&self, model: &Model) -> Result<()> {
        if self.min <= PIVOT_RTOL * self.max {
            return Err(pivot_error(model, self.min_dof, self.min, Some(self.max)));
        }
        Ok(())
    }
}

/// The error for the pivot `d` of velocity index `k`: not positive and finite (`max = None`),
/// or at most [`PIVOT_RTOL`] times the largest pivot `max`.
#[cold]
pub(crate) fn pivot_error(model: &Model, k: usize, d: f64, max: Option<f64>) -> Error {
    let why = match max {
        None => "is not positive and finite".to_string(),
        Some(m) => format!("is at most {PIVOT_RTOL:e} times the largest pivot {m:e}"),
    };
    Error::Singular {
        what: "mass matrix".into(),
        detail: format!(
            "pivot {d:e} at velocity index {k} (joint \"{}\") {why}; a massless subtree, or a \
             massless link between joints whose motions coincide?",
            model.names[model.dof_joint[k]]
        ),
    }
}

/// `h ← ` its `Lᵀ D L` factor in place (layout of [`factorize_ltl`]), with the singularity
/// test of [`Pivots`].
pub(crate) fn ltl_in_place(model: &Model, h: &mut DMatrix<f64>) -> Result<()> {
    let n = model.nv;
    let h = h.as_mut_slice();
    assert!(h.len() == n * n);
    let mut piv = Pivots::new();
    for k in (0..n).rev() {
        let hkk = h[k + n * k];
        if !pivot_ok(hkk) {
            return Err(pivot_error(model, k, hkk, None));
        }
        piv.record(k, hkk);
        let anc = model.ancestors_of_dof(k);
        let rk = 1.0 / hkk;
        let hp = h.as_mut_ptr();
        // SAFETY: k < n and its ancestors i, j < k come from `Model::dof_ancestors`, so every
        // index below is < n² = h.len() (asserted above).
        for (pos, &i) in anc.iter().enumerate() {
            unsafe {
                let hk = hp.add(n * k);
                let hi = hp.add(n * i);
                let hik = *hk.add(i);
                let a = hik * rk;
                // H(i, i) and H(i, j) for the ancestors j of i (the tail of k's list).
                *hi.add(i) -= a * hik;
                for &j in anc.get_unchecked(pos + 1..) {
                    *hi.add(j) -= a * *hk.add(j);
                }
                *hk.add(i) = a;
            }
        }
    }
    piv.finish(model)
}

/// Solves `M x = b` in place with the factor in `data.ltl` (see [`factorize_ltl`]).
pub fn solve_ltl(model: &Model, data: &Data, b: &mut DVector<f64>) -> Result<()> {
    data.check_tree(model)?;
    check_vec("b", b, model.nv)?;
    ltl_solve_in_place(model, &data.ltl, b.as_mut_slice());
    Ok(())
}

/// `x ← M⁻¹ x` with a `LᵀDL` factor `h`.
pub(crate) fn ltl_solve_in_place(model: &Model, h: &DMatrix<f64>, x: &mut [f64]) {
    let n = model.nv;
    let h = h.as_slice();
    assert!(x.len() == n && h.len() == n * n, "ltl_solve_in_place: dimension mismatch");
    // SAFETY (all `get_unchecked` below): i < n, and every ancestor index j < i < n comes from
    // `Model::dof_ancestors`, so j + n i < n² = h.len() and j < n = x.len().
    unsafe {
        for i in (0..n).rev() {
            let xi = *x.get_unchecked(i);
            if xi != 0.0 {
                for &j in model.ancestors_of_dof(i) {
                    *x.get_unchecked_mut(j) -= h.get_unchecked(j + n * i) * xi;
                }
            }
        }
        for i in 0..n {
            *x.get_unchecked_mut(i) /= h.get_unchecked(i + n * i);
        }
        for i in 0..n {
            let mut acc = *x.get_unchecked(i);
            for &j in model.ancestors_of_dof(i) {
                acc -= h.get_unchecked(j + n * i) * x.get_unchecked(j);
            }
            *x.get_unchecked_mut(i) = acc;
        }
    }
}

/// Solves `M X = B` column by column in place.
pub fn solve_ltl_matrix(model: &Model, data: &Data, b: &mut DMatrix<f64>) -> Result<()> {
    data.check_tree(model)?;
    if b.nrows() != model.nv {
        return Err(Error::Dimension { what: "B rows".into(), expected: model.nv, got: b.nrows() });
    }
    for mut col in b.column_iter_mut() {
        ltl_solve_in_place(model, &data.ltl, col.as_mut_slice());
    }
    Ok(())
}

/// Row `i ← scale·row i − Σ_{j ∈ others} coef(j) row j` on lanes, by chunks of 8, 4, 2, 1
/// vectors kept in registers and a masked ragged end.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn pull_row<V: F64x4>(
    x: *mut f64,
    ld: usize,
    len: usize,
    mask: V::Mask,
    i: usize,
    others: &[usize],
    coef: impl Fn(usize) -> f64 + Copy,
    scale: f64,
) {
    let nfull = len / 4;
    // SAFETY: the caller upholds this function's contract: `x` is valid for the rows < nv (stride
    // `ld`) and columns used, and every index from the model's ancestor / descendant lists is < nv.
    unsafe {
        let mut g = 0;
        while g + 8 <= nfull {
            pull_chunk::<V, 8, false>(x, ld, mask, i, 4 * g, others, coef, scale);
            g += 8;
        }
        if g + 4 <= nfull {
            pull_chunk::<V, 4, false>(x, ld, mask, i, 4 * g, others, coef, scale);
            g += 4;
        }
        if g + 2 <= nfull {
            pull_chunk::<V, 2, false>(x, ld, mask, i, 4 * g, others, coef, scale);
            g += 2;
        }
        if g < nfull {
            pull_chunk::<V, 1, false>(x, ld, mask, i, 4 * g, others, coef, scale);
        }
        if !len.is_multiple_of(4) {
            pull_chunk::<V, 1, true>(x, ld, mask, i, 4 * nfull, others, coef, scale);
        }
    }
}

/// `K` vectors of row `i` from column `t` (the last one masked if `MASKED`), see [`pull_row`].
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn pull_chunk<V: F64x4, const K: usize, const MASKED: bool>(
    x: *mut f64,
    ld: usize,
    mask: V::Mask,
    i: usize,
    t: usize,
    others: &[usize],
    coef: impl Fn(usize) -> f64,
    scale: f64,
) {
    // SAFETY: the caller upholds this function's contract: `x` is valid for the rows < nv (stride
    // `ld`) and columns used, and every index from the model's ancestor / descendant lists is < nv.
    unsafe {
        let sc = V::splat(scale);
        let xi = x.add(i * ld + t);
        let mut acc = [V::zero(); K];
        for (u, a) in acc.iter_mut().enumerate() {
            *a = sc.mul(ld4::<V, MASKED>(xi.add(4 * u), mask));
        }
        for &j in others {
            let l = V::splat(coef(j));
            let xj = x.add(j * ld + t);
            for (u, a) in acc.iter_mut().enumerate() {
                *a = l.neg_mul_add(ld4::<V, MASKED>(xj.add(4 * u), mask), *a);
            }
        }
        for (u, a) in acc.iter().enumerate() {
            if MASKED {
                (*a).maskstore(xi.add(4 * u), mask);
            } else {
                (*a).storeu(xi.add(4 * u));
            }
        }
    }
}

/// Four lanes from `p`, the ones of `mask` only if `MASKED`.
///
/// # Safety
/// `p` valid for reading those lanes.
#[inline(always)]
unsafe fn ld4<V: F64x4, const MASKED: bool>(p: *const f64, mask: V::Mask) -> V {
    // SAFETY: the function's contract.
    unsafe { if MASKED { V::maskload(p, mask) } else { V::loadu(p) } }
}

/// Strict descendant DoFs of every DoF (the transpose of [`Model::dof_ancestors`]), owned.
#[derive(Clone, Debug)]
pub(crate) struct DofDescendants {
    starts: Vec<usize>,
    list: Vec<usize>,
}

/// Borrowed descendant lists: DoF `j`'s strict descendants are `list[starts[j]..starts[j + 1]]`,
/// all `< nv` by construction (only built by [`fill_descendants`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct DescView<'a> {
    nv: usize,
    starts: &'a [usize],
    list: &'a [usize],
}

/// Fills `starts` (length ≥ `nv + 1`) and `list` (length ≥ `model.dof_ancestors.len()`) with
/// the descendant lists of `model` (the buffers may start uninitialised); `None` if they are
/// too short.
pub(crate) fn fill_descendants<'a>(
    model: &Model,
    starts: &'a mut [MaybeUninit<usize>],
    list: &'a mut [MaybeUninit<usize>],
) -> Option<DescView<'a>> {
    let n = model.nv;
    let na = model.dof_ancestors.len();
    if starts.len() < n + 1 || list.len() < na {
        return None;
    }
    for v in &mut starts[..n + 1] {
        v.write(0);
    }
    // SAFETY: all n + 1 entries were just initialised.
    let starts: &mut [usize] =
        unsafe { std::slice::from_raw_parts_mut(starts.as_mut_ptr().cast::<usize>(), n + 1) };
    for i in 0..n {
        for &j in model.ancestors_of_dof(i) {
            starts[j + 1] += 1;
        }
    }
    for j in 0..n {
        starts[j + 1] += starts[j];
    }
    // Place each DoF after the ones already put (starts[j] advances), then shift back. The
    // counts sum to na, so every entry of list[..na] is written exactly once.
    for i in 0..n {
        for &j in model.ancestors_of_dof(i) {
            list[starts[j]].write(i);
            starts[j] += 1;
        }
    }
    for j in (1..=n).rev() {
        starts[j] = starts[j - 1];
    }
    starts[0] = 0;
    // SAFETY: list[..na] has been fully initialised above.
    let list: &[usize] = unsafe { std::slice::from_raw_parts(list.as_ptr().cast::<usize>(), na) };
    Some(DescView { nv: n, starts, list })
}

impl DofDescendants {
    pub(crate) fn new(model: &Model) -> Self {
        let mut starts = vec![MaybeUninit::uninit(); model.nv + 1];
        let mut list = vec![MaybeUninit::uninit(); model.dof_ancestors.len()];
        let v =
            fill_descendants(model, &mut starts, &mut list).expect("buffers sized for the model");
        Self { starts: v.starts.to_vec(), list: v.list.to_vec() }
    }
    /// The lists, valid for models with this `nv`.
    pub(crate) fn view(&self) -> DescView<'_> {
        DescView { nv: self.starts.len() - 1, starts: &self.starts, list: &self.list }
    }
}

/// [`ltl_solve_rows`] with descendant lists ([`DescView`]), so that the first sweep
/// also pulls (`y_j = b_j − Σ_{i ≻ j} L_ij y_i`, accumulated in registers) instead of pushing.
#[allow(clippy::too_many_arguments)]
pub(crate) fn ltl_solve_rows_desc(
    model: &Model,
    h: &DMatrix<f64>,
    desc: DescView<'_>,
    x: &mut [f64],
    ld: usize,
    len: usize,
    alpha: f64,
) {
    let n = model.nv;
    let hs = h.as_slice();
    assert!(
        hs.len() == n * n && len <= ld && (n == 0 || (n - 1) * ld + len <= x.len()) && desc.nv == n,
        "ltl_solve_rows_desc: dimension mismatch"
    );
    // SAFETY: `x` holds rows 0..n of stride `ld` and length `len` (asserted above); ancestor
    // indices are < n (`ModelBuilder::build`) and descendant indices < desc.nv = n (by
    // construction); the CPU has AVX2 and FMA where `solve_rows_head_avx2` runs.
    unsafe {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            return solve_rows_head_avx2(model, hs, desc, x.as_mut_ptr(), ld, len, alpha, n);
        }
        solve_rows_head::<[f64; 4]>(model, hs, desc, x.as_mut_ptr(), ld, len, alpha, n)
    }
}

/// Model-constant workspace of the forward-dynamics derivatives: the descendant lists, the
/// end of each DoF's index range `sub_end[j]` (one past its last descendant, so that every
/// descendant of `j` lies in `j..sub_end[j]`), and the `nv × 3nv` row-stored right-hand sides.
#[derive(Clone, Debug)]
pub(crate) struct FdWs {
    pub(crate) desc: DofDescendants,
    pub(crate) sub_end: Vec<usize>,
    pub(crate) x: Vec<f64>,
}

impl FdWs {
    pub(crate) fn new(model: &Model) -> Self {
        let n = model.nv;
        let desc = DofDescendants::new(model);
        let v = desc.view();
        let sub_end = (0..n)
            .map(|j| {
                v.list[v.starts[j]..v.starts[j + 1]].iter().map(|&i| i + 1).max().unwrap_or(j + 1)
            })
            .collect();
        Self { desc, sub_end, x: vec![0.0; 3 * n * n] }
    }
}

/// The three forward-dynamics solves in one: `x` holds `nv` rows of length `3nv` (row `i` at
/// `x[3nv·i..]`): columns `0..2nv` a general right-hand side `B` (overwritten by `−M⁻¹ B`),
/// columns `2nv..3nv` the identity, of which only the upper triangle (`k ≥ i` in row `i`) must
/// be initialised (zeros, ones on the diagonal) and is overwritten by the upper triangle of
/// `M⁻¹`. The identity part exploits `(Lᵀ)⁻¹ e_k` being zero outside `k`'s ancestors: in the
/// first sweep row `i` only touches columns `i..sub_end[i]`, and the second sweep only forms
/// the upper triangle (which depends on the upper triangle alone, ancestors having lower index).
pub(crate) fn ltl_solve_fd(model: &Model, h: &DMatrix<f64>, ws: &mut FdWs) {
    let n = model.nv;
    let hs = h.as_slice();
    let v = ws.desc.view();
    assert!(
        hs.len() == n * n && ws.x.len() == 3 * n * n && v.nv == n && ws.sub_end.len() == n,
        "ltl_solve_fd: dimension mismatch"
    );
    // SAFETY: every row segment addressed lies in row i of `x` (columns < 3n, asserted
    // above), ancestor/descendant indices are < n, and `sub_end[i] ≤ n` (built from descendant
    // indices < n); the CPU has AVX2 and FMA where `solve_fd_avx2` runs.
    unsafe {
        #[cfg(target_arch = "x86_64")]
        if crate::simd::avx2_fma() {
            return solve_fd_avx2(model, hs, v, &ws.sub_end, ws.x.as_mut_ptr());
        }
        solve_fd::<[f64; 4]>(model, hs, v, &ws.sub_end, ws.x.as_mut_ptr())
    }
}

/// [`solve_fd`] compiled for AVX2/FMA.
///
/// # Safety
/// As [`solve_fd`]; the CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn solve_fd_avx2(
    model: &Model,
    h: &[f64],
    desc: DescView<'_>,
    sub_end: &[usize],
    x: *mut f64,
) {
    // SAFETY: the caller's contract.
    unsafe { solve_fd::<crate::simd::Avx4>(model, h, desc, sub_end, x) }
}

/// [`solve_rows_head`] compiled for AVX2/FMA.
///
/// # Safety
/// As [`solve_rows_head`]; the CPU has AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[allow(clippy::too_many_arguments)]
unsafe fn solve_rows_head_avx2(
    model: &Model,
    h: &[f64],
    desc: DescView<'_>,
    x: *mut f64,
    ld: usize,
    len: usize,
    alpha: f64,
    rows_end: usize,
) {
    // SAFETY: the caller's contract.
    unsafe { solve_rows_head::<crate::simd::Avx4>(model, h, desc, x, ld, len, alpha, rows_end) }
}

/// The three solves of [`ltl_solve_fd`] on lanes.
///
/// # Safety
/// `x` valid for `nv` rows of stride `3 nv`; ancestor and descendant indices `< nv`;
/// `sub_end[j] ≤ nv`.
#[inline(always)]
unsafe fn solve_fd<V: F64x4>(
    model: &Model,
    h: &[f64],
    desc: DescView<'_>,
    sub_end: &[usize],
    x: *mut f64,
) {
    let n = model.nv;
    let ld = 3 * n;
    let w = 2 * n;
    let h = h.as_ptr();
    let mask_w = V::mask(w % 4);
    let starts = &model.dof_ancestors_start;
    let all_anc = &model.dof_ancestors;
    // SAFETY: the caller upholds this function's contract: `x` is valid for the rows < nv (stride
    // `ld`) and columns used, and every index from the model's ancestor / descendant lists is < nv.
    unsafe {
        let xi0 = x.add(w);
        for j in (0..n).rev() {
            // Lᵀ y = b, general part: row j pulls its (final) descendants, L_ij at (j, i).
            let d = desc
                .list
                .get_unchecked(*desc.starts.get_unchecked(j)..*desc.starts.get_unchecked(j + 1));
            if !d.is_empty() {
                let hj = h.add(j);
                pull_row::<V>(x, ld, w, mask_w, j, d, |i| *hj.add(n * i), 1.0);
            }
            // Identity part: the final row j pushes its columns j..sub_end[j] to its ancestors.
            let anc = all_anc.get_unchecked(*starts.get_unchecked(j)..*starts.get_unchecked(j + 1));
            if anc.is_empty() {
                continue;
            }
            let len = *sub_end.get_unchecked(j) - j;
            let nfull = len / 4;
            let mask = V::mask(len % 4);
            let src = xi0.add(j * ld + j);
            let hj = h.add(n * j);
            for &a in anc {
                let l = V::splat(*hj.add(a));
                let dst = xi0.add(a * ld + j);
                for u in 0..nfull {
                    let p = dst.add(4 * u);
                    let s = V::loadu(src.add(4 * u));
                    (l.neg_mul_add(s, V::loadu(p))).storeu(p);
                }
                if len % 4 != 0 {
                    let p = dst.add(4 * nfull);
                    let s = V::maskload(src.add(4 * nfull), mask);
                    let dv = V::maskload(p, mask);
                    l.neg_mul_add(s, dv).maskstore(p, mask);
                }
            }
        }
        // z = D⁻¹ y (times −1 on the general part), then L x = z: row i pulls its ancestors;
        // on the identity part only columns i..n.
        for i in 0..n {
            let anc = all_anc.get_unchecked(*starts.get_unchecked(i)..*starts.get_unchecked(i + 1));
            let hi = h.add(n * i);
            let dinv = 1.0 / *hi.add(i);
            pull_row::<V>(x, ld, w, mask_w, i, anc, |j| *hi.add(j), -dinv);
            let len = n - i;
            pull_row::<V>(xi0.add(i), ld, len, V::mask(len % 4), i, anc, |j| *hi.add(j), dinv);
        }
    }
}

/// Portable version of [`solve_fd_avx2`] (same sweeps, scalar).
/// The two sweeps of [`ltl_solve_rows_desc`] on lanes.
///
/// # Safety
/// `x` valid for `nv` rows of stride `ld` and length `len`; ancestor and descendant indices
/// `< nv`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
unsafe fn solve_rows_head<V: F64x4>(
    model: &Model,
    h: &[f64],
    desc: DescView<'_>,
    x: *mut f64,
    ld: usize,
    len: usize,
    alpha: f64,
    rows_end: usize,
) {
    let n = model.nv;
    let h = h.as_ptr();
    let mask = V::mask(len % 4);
    let starts = &model.dof_ancestors_start;
    let all_anc = &model.dof_ancestors;
    // SAFETY: the caller upholds this function's contract: `x` is valid for the rows < nv (stride
    // `ld`) and columns used, and every index from the model's ancestor / descendant lists is < nv.
    unsafe {
        // Lᵀ y = b: row j pulls its (already final) descendants, L_ij stored at (j, i).
        for j in (0..n).rev() {
            let d = desc
                .list
                .get_unchecked(*desc.starts.get_unchecked(j)..*desc.starts.get_unchecked(j + 1));
            if !d.is_empty() {
                let hj = h.add(j);
                pull_row::<V>(x, ld, len, mask, j, d, |i| *hj.add(n * i), 1.0);
            }
        }
        // z = α D⁻¹ y, then L x = z on rows 0..rows_end.
        for i in 0..rows_end {
            let anc = all_anc.get_unchecked(*starts.get_unchecked(i)..*starts.get_unchecked(i + 1));
            let hi = h.add(n * i);
            let dinv = alpha / *hi.add(i);
            pull_row::<V>(x, ld, len, mask, i, anc, |j| *hi.add(j), dinv);
        }
    }
}
