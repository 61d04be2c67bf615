//! Spatial-matrix extension of the cross products (notes, section "Tensorial Identities and
//! Properties").
//!
//! A spatial motion matrix `U ∈ M^{6×n}` or force matrix `F ∈ F^{6×m}` is a `6×n` matrix whose
//! columns are spatial vectors `[angular; linear]`, represented as [`Matrix6xX<f64>`] (any
//! 6-row nalgebra matrix is accepted). The tilde operators turn such a matrix into a third-order
//! [`Tensor3`] of dimensions `6×6×n`, page `k` being the usual operator of column `k`:
//!
//! | notes        | here                     | page `k`                |
//! |--------------|--------------------------|-------------------------|
//! | `U ×̃`        | [`cross_m_tensor`]       | `U[:,k] ×`              |
//! | `U ×̃*`       | [`cross_f_tensor`]       | `U[:,k] ×*`             |
//! | `F ×̄̃*`       | [`crff_tensor`]          | `F[:,k] ×̄*`             |
//! | `𝓑(I, U)`    | [`coriolis_b_tensor`]    | `B(I, U[:,k])`          |
//!
//! Products with matrices use [`Tensor3::mul_mat`] (`𝒜 B`) and [`Tensor3::mat_mul`] (`B 𝒜`);
//! e.g. `(V ×̃) U = cross_m_tensor(V).mul_mat(U)`, whose page `k`, column `j` is
//! `V[:,k] × U[:,j]`. These functions are meant for verification and documentation (the
//! algorithms work column by column), so they favour clarity over speed.

use super::{Force, Inertia, Motion, coriolis_b};
use crate::tensor::Tensor3;
use nalgebra::{Dim, Matrix, Matrix6, Matrix6xX, RawStorage, U6, Vector6};

/// Column `k` of a 6-row matrix as a 6-vector.
fn column<C: Dim, S: RawStorage<f64, U6, C>>(m: &Matrix<f64, U6, C, S>, k: usize) -> Vector6<f64> {
    Vector6::from_fn(|i, _| m[(i, k)])
}

/// Column `k` of a spatial motion matrix, as a [`Motion`].
///
/// # Panics
/// If `k >= u.ncols()`.
pub fn motion_column<C: Dim, S: RawStorage<f64, U6, C>>(
    u: &Matrix<f64, U6, C, S>,
    k: usize,
) -> Motion {
    Motion::from_vec6(&column(u, k))
}

/// Column `k` of a spatial force matrix, as a [`Force`].
///
/// # Panics
/// If `k >= f.ncols()`.
pub fn force_column<C: Dim, S: RawStorage<f64, U6, C>>(
    f: &Matrix<f64, U6, C, S>,
    k: usize,
) -> Force {
    Force::from_vec6(&column(f, k))
}

/// The spatial motion matrix with the given columns.
pub fn motion_matrix_from(cols: &[Motion]) -> Matrix6xX<f64> {
    Matrix6xX::from_fn(cols.len(), |i, k| cols[k].to_vec6()[i])
}

/// The spatial force matrix with the given columns.
pub fn force_matrix_from(cols: &[Force]) -> Matrix6xX<f64> {
    Matrix6xX::from_fn(cols.len(), |i, k| cols[k].to_vec6()[i])
}

/// The `6×6×n` tensor whose page `k` is `op(column k)`.
fn stack<C: Dim, S: RawStorage<f64, U6, C>>(
    m: &Matrix<f64, U6, C, S>,
    op: impl Fn(&Vector6<f64>) -> Matrix6<f64>,
) -> Tensor3 {
    let mut t = Tensor3::zeros(6, 6, m.ncols());
    for k in 0..m.ncols() {
        t.page_mut(k).copy_from(&op(&column(m, k)));
    }
    t
}

/// `U ×̃ ∈ ℝ^{6×6×n}`: page `k` is `U[:,k] ×` (eq. cross_defn on each column).
pub fn cross_m_tensor<C: Dim, S: RawStorage<f64, U6, C>>(u: &Matrix<f64, U6, C, S>) -> Tensor3 {
    stack(u, |c| Motion::from_vec6(c).cross_matrix())
}

/// `U ×̃* ∈ ℝ^{6×6×n}`: page `k` is `U[:,k] ×*` (eq. cross_f_defn on each column).
pub fn cross_f_tensor<C: Dim, S: RawStorage<f64, U6, C>>(u: &Matrix<f64, U6, C, S>) -> Tensor3 {
    stack(u, |c| Motion::from_vec6(c).cross_force_matrix())
}

/// `F ×̄̃* ∈ ℝ^{6×6×m}`: page `k` is `F[:,k] ×̄*` (eq. crff_oper on each column), so that
/// `(F ×̄̃*) U` has page `k`, column `j` equal to `U[:,j] ×* F[:,k]`.
pub fn crff_tensor<C: Dim, S: RawStorage<f64, U6, C>>(f: &Matrix<f64, U6, C, S>) -> Tensor3 {
    stack(f, |c| Force::from_vec6(c).crff_matrix())
}

/// `𝓑(I, U) ∈ ℝ^{6×6×n}`: page `k` is `B(I, U[:,k])` (eq. bkm_term_defn on each column;
/// the notes write it `½((U ×̃*) I − I (U ×̃) + (I U) ×̄̃*)`).
pub fn coriolis_b_tensor<C: Dim, S: RawStorage<f64, U6, C>>(
    i: &Inertia,
    u: &Matrix<f64, U6, C, S>,
) -> Tensor3 {
    stack(u, |c| coriolis_b(i, &Motion::from_vec6(c)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn pages_and_columns() {
        let a = Motion::new(Vector3::new(1.0, 2.0, 3.0), Vector3::new(-1.0, 0.5, 2.0));
        let b = Motion::new(Vector3::new(0.3, -2.0, 1.0), Vector3::new(4.0, 0.0, -1.0));
        let u = motion_matrix_from(&[a, b]);
        assert_eq!(motion_column(&u, 1), b);
        let t = cross_m_tensor(&u);
        assert_eq!(t.dims(), (6, 6, 2));
        assert_eq!(
            t.page(1).clone_owned(),
            nalgebra::DMatrix::from_column_slice(6, 6, b.cross_matrix().as_slice())
        );
        // (U ×̃) U: page k, column j = U_k × U_j.
        let uu = t.mul_mat(&u);
        let c = a.cross(&b).to_vec6();
        for r in 0..6 {
            assert_eq!(uu[(r, 1, 0)], c[r]);
        }
        let f = force_matrix_from(&[Force::new(a.ang, b.lin)]);
        assert_eq!(force_column(&f, 0), Force::new(a.ang, b.lin));
        assert_eq!(crff_tensor(&f).dims(), (6, 6, 1));
        assert_eq!(
            cross_f_tensor(&u).page(0).clone_owned(),
            nalgebra::DMatrix::from_column_slice(6, 6, a.cross_force_matrix().as_slice())
        );
    }
}
