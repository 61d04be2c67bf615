//! Dense third-order tensors, as used by the notes' section "Tensorial Identities and
//! Properties".
//!
//! A [`Tensor3`] `𝒜 ∈ ℝ^{n1×n2×n3}` is stored **column-major like Eigen's `Tensor`**: element
//! `(i, j, k)` lives at `data[i + n1·j + n1·n2·k]`. Hence
//!
//! * a *page* `𝒜[:, :, k]` (the `n1×n2` matrix of fixed `k`, "the 1-2 dimension" of the notes)
//!   is one contiguous column-major block, exposed without copying as an nalgebra matrix view by
//!   [`Tensor3::page`] / [`Tensor3::page_mut`];
//! * a *fibre* `𝒜[:, j, k]` (a column of a page) is contiguous too ([`Tensor3::fibre`]).
//!
//! The operations follow the notes:
//!
//! | notes                   | here                   | definition                  |
//! |-------------------------|------------------------|-----------------------------|
//! | `𝒵 = 𝒜 B` tensor-matrix | [`Tensor3::mul_mat`]   | `𝒵_ijk = Σ_l 𝒜_ilk B_lj`    |
//! | `𝒴 = B 𝒜` matrix-tensor | [`Tensor3::mat_mul`]   | `𝒴_ijk = Σ_l B_il 𝒜_ljk`    |
//! | `𝒜^T̃` (transpose 1-2)   | [`Tensor3::rotate_t`]  | `(𝒜^T̃)_jik = 𝒜_ijk`        |
//! | `𝒜^R̃` (rotation 2-3)    | [`Tensor3::rotate_r`]  | `(𝒜^R̃)_ikj = 𝒜_ijk`        |
//! | `𝒜^{R̃,T̃}` (R then T)    | [`Tensor3::rotate_rt`] | `(𝒜^{R̃,T̃})_kij = 𝒜_ijk`    |
//!
//! A matrix `M ∈ ℝ^{a×b}` is identified with the single-page tensor `a×b×1`
//! ([`Tensor3::from_matrix`]); e.g. the notes' `(𝒜 x)^R̃` for a vector `x` is the `n1×n3` matrix
//! [`Tensor3::contract2`].

use nalgebra::{DMatrix, DMatrixView, DMatrixViewMut, DVectorView, Dim, Matrix, RawStorage};
use std::ops::{Add, Index, IndexMut, Mul, Neg, Sub};

/// A dense `n1×n2×n3` tensor of `f64`, column-major (element `(i,j,k)` at
/// `data[i + n1·j + n1·n2·k]`, the layout of Eigen's `Tensor<double, 3>`).
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor3 {
    n1: usize,
    n2: usize,
    n3: usize,
    data: Vec<f64>,
}

impl Tensor3 {
    /// The zero tensor of dimensions `n1×n2×n3`.
    pub fn zeros(n1: usize, n2: usize, n3: usize) -> Self {
        Self { n1, n2, n3, data: vec![0.0; n1 * n2 * n3] }
    }

    /// The tensor with element `(i, j, k)` equal to `f(i, j, k)`.
    pub fn from_fn(
        n1: usize,
        n2: usize,
        n3: usize,
        mut f: impl FnMut(usize, usize, usize) -> f64,
    ) -> Self {
        let mut data = Vec::with_capacity(n1 * n2 * n3);
        for k in 0..n3 {
            for j in 0..n2 {
                for i in 0..n1 {
                    data.push(f(i, j, k));
                }
            }
        }
        Self { n1, n2, n3, data }
    }

    /// Wraps column-major data (element `(i,j,k)` at `data[i + n1·j + n1·n2·k]`).
    ///
    /// # Panics
    /// If `data.len() != n1·n2·n3`.
    pub fn from_vec(n1: usize, n2: usize, n3: usize, data: Vec<f64>) -> Self {
        assert_eq!(data.len(), n1 * n2 * n3, "Tensor3::from_vec: wrong data length");
        Self { n1, n2, n3, data }
    }

    /// The single-page tensor `a×b×1` of an `a×b` matrix (the notes identify the two).
    pub fn from_matrix<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(m: &Matrix<f64, R, C, S>) -> Self {
        Self::from_fn(m.nrows(), m.ncols(), 1, |i, j, _| m[(i, j)])
    }

    /// The tensor whose page `k` is `pages[k]`.
    ///
    /// # Panics
    /// If the pages do not all have the same shape. An empty slice gives a `0×0×0` tensor.
    pub fn from_pages(pages: &[DMatrix<f64>]) -> Self {
        let (n1, n2) = pages.first().map_or((0, 0), |p| p.shape());
        let mut t = Self::zeros(n1, n2, pages.len());
        for (k, p) in pages.iter().enumerate() {
            assert_eq!(p.shape(), (n1, n2), "Tensor3::from_pages: pages of different shapes");
            t.page_mut(k).copy_from(p);
        }
        t
    }

    /// From nested lists `t[i][j][k]` (the JSON layout of the fixtures); `None` if ragged.
    pub fn from_nested(t: &[Vec<Vec<f64>>]) -> Option<Self> {
        let n1 = t.len();
        let n2 = t.first().map_or(0, |a| a.len());
        let n3 = t.first().and_then(|a| a.first()).map_or(0, |b| b.len());
        if t.iter().any(|a| a.len() != n2 || a.iter().any(|b| b.len() != n3)) {
            return None;
        }
        Some(Self::from_fn(n1, n2, n3, |i, j, k| t[i][j][k]))
    }

    /// Nested lists `v[i][j][k]` (for JSON).
    pub fn to_nested(&self) -> Vec<Vec<Vec<f64>>> {
        (0..self.n1)
            .map(|i| {
                (0..self.n2).map(|j| (0..self.n3).map(|k| self[(i, j, k)]).collect()).collect()
            })
            .collect()
    }

    /// Dimensions `(n1, n2, n3)`.
    #[inline]
    pub fn dims(&self) -> (usize, usize, usize) {
        (self.n1, self.n2, self.n3)
    }

    #[inline]
    fn offset(&self, i: usize, j: usize, k: usize) -> usize {
        assert!(
            i < self.n1 && j < self.n2 && k < self.n3,
            "Tensor3 index ({i}, {j}, {k}) out of bounds for dims ({}, {}, {})",
            self.n1,
            self.n2,
            self.n3
        );
        i + self.n1 * (j + self.n2 * k)
    }

    /// Element `(i, j, k)`.
    ///
    /// # Panics
    /// If an index is out of bounds.
    #[inline]
    pub fn get(&self, i: usize, j: usize, k: usize) -> f64 {
        self.data[self.offset(i, j, k)]
    }

    /// Sets element `(i, j, k)` to `x`.
    ///
    /// # Panics
    /// If an index is out of bounds.
    #[inline]
    pub fn set(&mut self, i: usize, j: usize, k: usize, x: f64) {
        let o = self.offset(i, j, k);
        self.data[o] = x;
    }

    /// The column-major storage (element `(i,j,k)` at `i + n1·j + n1·n2·k`).
    #[inline]
    pub fn as_slice(&self) -> &[f64] {
        &self.data
    }

    /// The column-major storage, mutable.
    #[inline]
    pub fn as_mut_slice(&mut self) -> &mut [f64] {
        &mut self.data
    }

    /// Page `k`: the `n1×n2` matrix `𝒜[:, :, k]` (a view of contiguous storage).
    ///
    /// # Panics
    /// If `k >= n3`.
    #[inline]
    pub fn page(&self, k: usize) -> DMatrixView<'_, f64> {
        assert!(k < self.n3, "Tensor3::page: page {k} out of bounds ({})", self.n3);
        let s = self.n1 * self.n2;
        DMatrixView::from_slice(&self.data[s * k..s * (k + 1)], self.n1, self.n2)
    }

    /// Page `k`, mutable.
    ///
    /// # Panics
    /// If `k >= n3`.
    #[inline]
    pub fn page_mut(&mut self, k: usize) -> DMatrixViewMut<'_, f64> {
        assert!(k < self.n3, "Tensor3::page_mut: page {k} out of bounds ({})", self.n3);
        let s = self.n1 * self.n2;
        DMatrixViewMut::from_slice(&mut self.data[s * k..s * (k + 1)], self.n1, self.n2)
    }

    /// The fibre `𝒜[:, j, k]` (column `j` of page `k`, contiguous, length `n1`).
    ///
    /// # Panics
    /// If `j >= n2` or `k >= n3`.
    #[inline]
    pub fn fibre(&self, j: usize, k: usize) -> DVectorView<'_, f64> {
        assert!(j < self.n2 && k < self.n3, "Tensor3::fibre: ({j}, {k}) out of bounds");
        let o = self.n1 * (j + self.n2 * k);
        DVectorView::from_slice(&self.data[o..o + self.n1], self.n1)
    }

    /// Sets every element to `x`.
    #[inline]
    pub fn fill(&mut self, x: f64) {
        self.data.fill(x);
    }

    /// `𝒜^T̃`, the transpose along the 1-2 dimension (each page transposed):
    /// `result[j][i][k] = self[i][j][k]`, dimensions `n2×n1×n3`.
    pub fn rotate_t(&self) -> Tensor3 {
        Self::from_fn(self.n2, self.n1, self.n3, |j, i, k| self[(i, j, k)])
    }

    /// `𝒜^R̃`, the rotation along the 2-3 dimension: `result[i][k][j] = self[i][j][k]`,
    /// dimensions `n1×n3×n2`.
    pub fn rotate_r(&self) -> Tensor3 {
        Self::from_fn(self.n1, self.n3, self.n2, |i, k, j| self[(i, j, k)])
    }

    /// `𝒜^{R̃,T̃}`: [`rotate_r`](Self::rotate_r) followed by [`rotate_t`](Self::rotate_t), i.e.
    /// `result[k][i][j] = self[i][j][k]` (the notes: "if `𝒜^{RT} = ℬ` then `𝒜_ijk = ℬ_kij`"),
    /// dimensions `n3×n1×n2`.
    pub fn rotate_rt(&self) -> Tensor3 {
        Self::from_fn(self.n3, self.n1, self.n2, |k, i, j| self[(i, j, k)])
    }

    /// Tensor-matrix product `𝒵 = 𝒜 B`, `𝒵_ijk = Σ_l 𝒜_ilk B_lj` (each page times `B`);
    /// dimensions `n1 × B.ncols() × n3`.
    ///
    /// # Panics
    /// If `B.nrows() != n2`.
    pub fn mul_mat<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
        &self,
        b: &Matrix<f64, R, C, S>,
    ) -> Tensor3 {
        assert_eq!(b.nrows(), self.n2, "Tensor3::mul_mat: dimension mismatch");
        let m = b.ncols();
        let mut z = Tensor3::zeros(self.n1, m, self.n3);
        for k in 0..self.n3 {
            for j in 0..m {
                let zo = self.n1 * (j + m * k);
                for l in 0..self.n2 {
                    let blj = b[(l, j)];
                    let ao = self.n1 * (l + self.n2 * k);
                    for i in 0..self.n1 {
                        z.data[zo + i] += self.data[ao + i] * blj;
                    }
                }
            }
        }
        z
    }

    /// Matrix-tensor product `𝒴 = A 𝒯`, `𝒴_ijk = Σ_l A_il 𝒯_ljk` (`A` times each page);
    /// dimensions `A.nrows() × n2 × n3`.
    ///
    /// # Panics
    /// If `A.ncols() != t.n1`.
    pub fn mat_mul<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
        a: &Matrix<f64, R, C, S>,
        t: &Tensor3,
    ) -> Tensor3 {
        assert_eq!(a.ncols(), t.n1, "Tensor3::mat_mul: dimension mismatch");
        let r = a.nrows();
        let mut y = Tensor3::zeros(r, t.n2, t.n3);
        for k in 0..t.n3 {
            for j in 0..t.n2 {
                let yo = r * (j + t.n2 * k);
                let to = t.n1 * (j + t.n2 * k);
                for l in 0..t.n1 {
                    let tl = t.data[to + l];
                    for i in 0..r {
                        y.data[yo + i] += a[(i, l)] * tl;
                    }
                }
            }
        }
        y
    }

    /// Contraction on the third index: the `n1×n2` matrix `Σ_k 𝒜_ijk x_k`.
    ///
    /// # Panics
    /// If `x.len() != n3`.
    pub fn contract3<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
        &self,
        x: &Matrix<f64, R, C, S>,
    ) -> DMatrix<f64> {
        assert_eq!(x.len(), self.n3, "Tensor3::contract3: dimension mismatch");
        let mut out = DMatrix::zeros(self.n1, self.n2);
        for k in 0..self.n3 {
            out += self.page(k) * x[k];
        }
        out
    }

    /// Contraction on the second index: the `n1×n3` matrix `Σ_j 𝒜_ijk x_j`
    /// (column `k` is `page(k) x`; this is the notes' `(𝒜 x)^R̃` seen as a matrix).
    ///
    /// # Panics
    /// If `x.len() != n2`.
    pub fn contract2<R: Dim, C: Dim, S: RawStorage<f64, R, C>>(
        &self,
        x: &Matrix<f64, R, C, S>,
    ) -> DMatrix<f64> {
        assert_eq!(x.len(), self.n2, "Tensor3::contract2: dimension mismatch");
        let mut out = DMatrix::zeros(self.n1, self.n3);
        for k in 0..self.n3 {
            for j in 0..self.n2 {
                let xj = x[j];
                for i in 0..self.n1 {
                    out[(i, k)] += self[(i, j, k)] * xj;
                }
            }
        }
        out
    }

    /// Largest absolute element (0 for an empty tensor).
    pub fn max_abs(&self) -> f64 {
        self.data.iter().fold(0.0, |m, x| m.max(x.abs()))
    }

    /// Largest absolute element-wise difference; `f64::INFINITY` if the dimensions differ.
    pub fn max_abs_diff(&self, other: &Tensor3) -> f64 {
        if self.dims() != other.dims() {
            return f64::INFINITY;
        }
        self.data.iter().zip(&other.data).fold(0.0, |m, (a, b)| m.max((a - b).abs()))
    }
}

/// `t[(i, j, k)]`: element `(i, j, k)`.
///
/// # Panics
/// If an index is out of bounds (`i ≥ n1`, `j ≥ n2` or `k ≥ n3`), as slice indexing does.
impl Index<(usize, usize, usize)> for Tensor3 {
    type Output = f64;
    #[inline]
    fn index(&self, (i, j, k): (usize, usize, usize)) -> &f64 {
        &self.data[self.offset(i, j, k)]
    }
}

/// `t[(i, j, k)] = x`.
///
/// # Panics
/// If an index is out of bounds, as for [`Index`].
impl IndexMut<(usize, usize, usize)> for Tensor3 {
    #[inline]
    fn index_mut(&mut self, (i, j, k): (usize, usize, usize)) -> &mut f64 {
        let o = self.offset(i, j, k);
        &mut self.data[o]
    }
}

impl Add for &Tensor3 {
    type Output = Tensor3;
    /// Element-wise sum. Panics if the dimensions differ.
    fn add(self, o: &Tensor3) -> Tensor3 {
        assert_eq!(self.dims(), o.dims(), "Tensor3 + Tensor3: dimension mismatch");
        let data = self.data.iter().zip(&o.data).map(|(a, b)| a + b).collect();
        Tensor3 { n1: self.n1, n2: self.n2, n3: self.n3, data }
    }
}

impl Sub for &Tensor3 {
    type Output = Tensor3;
    /// Element-wise difference. Panics if the dimensions differ.
    fn sub(self, o: &Tensor3) -> Tensor3 {
        assert_eq!(self.dims(), o.dims(), "Tensor3 - Tensor3: dimension mismatch");
        let data = self.data.iter().zip(&o.data).map(|(a, b)| a - b).collect();
        Tensor3 { n1: self.n1, n2: self.n2, n3: self.n3, data }
    }
}

impl Neg for &Tensor3 {
    type Output = Tensor3;
    fn neg(self) -> Tensor3 {
        self * -1.0
    }
}

impl Mul<f64> for &Tensor3 {
    type Output = Tensor3;
    fn mul(self, s: f64) -> Tensor3 {
        let data = self.data.iter().map(|a| a * s).collect();
        Tensor3 { n1: self.n1, n2: self.n2, n3: self.n3, data }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;
    use nalgebra::{DVector, Matrix2x3};

    fn random(rng: &mut Rng, n1: usize, n2: usize, n3: usize) -> Tensor3 {
        Tensor3::from_fn(n1, n2, n3, |_, _, _| rng.normal())
    }

    fn random_mat(rng: &mut Rng, r: usize, c: usize) -> DMatrix<f64> {
        DMatrix::from_fn(r, c, |_, _| rng.normal())
    }

    #[test]
    fn layout_is_column_major() {
        let t = Tensor3::from_fn(2, 3, 4, |i, j, k| (100 * i + 10 * j + k) as f64);
        assert_eq!(t.dims(), (2, 3, 4));
        for k in 0..4 {
            for j in 0..3 {
                for i in 0..2 {
                    let x = (100 * i + 10 * j + k) as f64;
                    assert_eq!(t.as_slice()[i + 2 * j + 6 * k], x);
                    assert_eq!(t.get(i, j, k), x);
                    assert_eq!(t[(i, j, k)], x);
                    assert_eq!(t.page(k)[(i, j)], x);
                    assert_eq!(t.fibre(j, k)[i], x);
                }
            }
        }
        assert_eq!(Tensor3::from_vec(2, 3, 4, t.as_slice().to_vec()), t);
    }

    #[test]
    fn set_index_mut_fill_page_mut() {
        let mut t = Tensor3::zeros(3, 2, 2);
        t.set(2, 1, 0, 5.0);
        t[(0, 0, 1)] = -1.0;
        assert_eq!(t.as_slice()[2 + 3], 5.0);
        assert_eq!(t.as_slice()[6], -1.0);
        t.page_mut(1).fill(2.0);
        assert_eq!(t.page(1).sum(), 12.0);
        assert_eq!(t.page(0).sum(), 5.0);
        t.as_mut_slice()[0] = 7.0;
        assert_eq!(t[(0, 0, 0)], 7.0);
        t.fill(1.5);
        assert!(t.as_slice().iter().all(|&x| x == 1.5));
    }

    #[test]
    #[should_panic]
    fn out_of_bounds_panics() {
        let t = Tensor3::zeros(2, 2, 2);
        let _ = t.get(0, 2, 0);
    }

    #[test]
    fn nested_round_trip() {
        let mut rng = Rng::new(1);
        let t = random(&mut rng, 3, 1, 2);
        let v = t.to_nested();
        assert_eq!(v.len(), 3);
        assert_eq!(v[2][0][1], t[(2, 0, 1)]);
        assert_eq!(Tensor3::from_nested(&v), Some(t));
        assert_eq!(Tensor3::from_nested(&[vec![vec![1.0]], vec![vec![1.0, 2.0]]]), None);
    }

    #[test]
    fn rotations() {
        let mut rng = Rng::new(2);
        let a = random(&mut rng, 2, 3, 4);
        let t = a.rotate_t();
        let r = a.rotate_r();
        let rt = a.rotate_rt();
        assert_eq!(t.dims(), (3, 2, 4));
        assert_eq!(r.dims(), (2, 4, 3));
        assert_eq!(rt.dims(), (4, 2, 3));
        for i in 0..2 {
            for j in 0..3 {
                for k in 0..4 {
                    assert_eq!(t[(j, i, k)], a[(i, j, k)]);
                    assert_eq!(r[(i, k, j)], a[(i, j, k)]);
                    assert_eq!(rt[(k, i, j)], a[(i, j, k)]);
                }
            }
        }
        // R then T, involutions, and pages of T are transposed pages.
        assert_eq!(a.rotate_r().rotate_t(), rt);
        assert_eq!(t.rotate_t(), a);
        assert_eq!(r.rotate_r(), a);
        assert_eq!(t.page(3).clone_owned(), a.page(3).transpose());
    }

    #[test]
    fn products_match_definitions_and_pagewise() {
        let mut rng = Rng::new(3);
        let a = random(&mut rng, 3, 4, 2);
        let b = random_mat(&mut rng, 4, 5);
        let z = a.mul_mat(&b);
        assert_eq!(z.dims(), (3, 5, 2));
        for k in 0..2 {
            assert!((z.page(k) - a.page(k) * &b).amax() < 1e-14);
            for i in 0..3 {
                for j in 0..5 {
                    let s: f64 = (0..4).map(|l| a[(i, l, k)] * b[(l, j)]).sum();
                    assert!((z[(i, j, k)] - s).abs() < 1e-14);
                }
            }
        }
        let m = random_mat(&mut rng, 6, 3);
        let y = Tensor3::mat_mul(&m, &a);
        assert_eq!(y.dims(), (6, 4, 2));
        for k in 0..2 {
            assert!((y.page(k) - &m * a.page(k)).amax() < 1e-14);
        }
        // Fixed-size matrices work too.
        let f = Matrix2x3::new(1.0, 2.0, 3.0, 4.0, 5.0, 6.0);
        let y2 = Tensor3::mat_mul(&f, &a);
        assert!((y2.page(1) - f * a.page(1)).amax() < 1e-14);
    }

    #[test]
    fn contractions() {
        let mut rng = Rng::new(4);
        let a = random(&mut rng, 3, 4, 5);
        let x5 = DVector::from_fn(5, |_, _| rng.normal());
        let x4 = DVector::from_fn(4, |_, _| rng.normal());
        let c3 = a.contract3(&x5);
        let c2 = a.contract2(&x4);
        assert_eq!(c3.shape(), (3, 4));
        assert_eq!(c2.shape(), (3, 5));
        for i in 0..3 {
            for j in 0..4 {
                let s: f64 = (0..5).map(|k| a[(i, j, k)] * x5[k]).sum();
                assert!((c3[(i, j)] - s).abs() < 1e-13);
            }
            for k in 0..5 {
                let s: f64 = (0..4).map(|j| a[(i, j, k)] * x4[j]).sum();
                assert!((c2[(i, k)] - s).abs() < 1e-13);
            }
        }
        // (A x)^R seen as a matrix.
        let ax = a.mul_mat(&x4).rotate_r();
        assert_eq!(ax.dims(), (3, 5, 1));
        assert!((ax.page(0) - &c2).amax() < 1e-14);
    }

    #[test]
    fn arithmetic_and_diffs() {
        let mut rng = Rng::new(5);
        let a = random(&mut rng, 2, 2, 3);
        let b = random(&mut rng, 2, 2, 3);
        let s = &a + &b;
        let d = &s - &b;
        assert!(d.max_abs_diff(&a) < 1e-15);
        assert_eq!((&(-&a) + &a).max_abs(), 0.0);
        assert_eq!((&a * 2.0)[(1, 1, 2)], 2.0 * a[(1, 1, 2)]);
        assert_eq!(a.max_abs_diff(&Tensor3::zeros(2, 2, 2)), f64::INFINITY);
        let m = random_mat(&mut rng, 2, 2);
        let single = Tensor3::from_matrix(&m);
        assert_eq!(single.dims(), (2, 2, 1));
        assert_eq!(single.page(0).clone_owned(), m);
        let pages = Tensor3::from_pages(&[m.clone(), m.transpose()]);
        assert_eq!(pages.page(1).clone_owned(), m.transpose());
    }
}
