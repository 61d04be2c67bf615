//! The box-constrained QP of box-FDDP: `min_x ½ xᵀ H x + qᵀ x` s.t. `lb ≤ x ≤ ub`, by the
//! projected Newton method of Tassa, Mansard and Todorov (ICRA 2014, "Control-limited
//! differential dynamic programming"), with Crocoddyl's parameters (100 iterations, Armijo
//! ratio 0.1, gradient tolerance `1e-5`, step lengths `2^{−k}`, `k = 0..9`).
//!
//! Each iteration:
//! 1. `g = q + H x`; the clamped set `c = {j : x_j = lb_j ∧ g_j > 0, or x_j = ub_j ∧ g_j < 0}`,
//!    the free set `f` its complement;
//! 2. the Newton step on the free set: `Δx_f = −H_ff⁻¹ (q_f + H_ff x_f + H_fc x_c)`
//!    (Cholesky of `H_ff`), `Δx_c = 0`;
//! 3. projected line search: `x ← clamp(x + α Δx)` for the first `α` with
//!    `f(x) − f(x_new) > 0.1 gᵀ(x − x_new)`;
//! 4. stop when `‖q_f + H_ff x_f + H_fc x_c‖_∞ ≤ 1e-5`.

use nalgebra::{DMatrix, DVector};

/// Outcome of a box-QP solve.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BoxQpResult {
    /// Whether every Cholesky factorisation succeeded.
    pub ok: bool,
}

/// A box-QP solver with its buffers (nothing allocated per solve).
#[derive(Clone, Debug)]
pub struct BoxQp {
    /// The solution.
    pub x: DVector<f64>,
    /// The free indices of the last iteration.
    pub free: Vec<usize>,
    /// The clamped indices of the last iteration.
    pub clamped: Vec<usize>,
    hff: DMatrix<f64>,
    hff_inv: DMatrix<f64>,
    qf: DVector<f64>,
    g: DVector<f64>,
    dx: DVector<f64>,
    xnew: DVector<f64>,
    hx: DVector<f64>,
    /// Iterations (default 100).
    pub maxiter: usize,
    /// Armijo ratio (default 0.1).
    pub th_acceptstep: f64,
    /// Gradient tolerance (default `1e-5`).
    pub th_grad: f64,
}

impl BoxQp {
    /// A solver for `n` variables (`ndx` is the row count of the gains it later forms).
    pub fn new(n: usize, _ndx: usize) -> Self {
        BoxQp {
            x: DVector::zeros(n),
            free: Vec::with_capacity(n),
            clamped: Vec::with_capacity(n),
            hff: DMatrix::zeros(n, n),
            hff_inv: DMatrix::zeros(n, n),
            qf: DVector::zeros(n),
            g: DVector::zeros(n),
            dx: DVector::zeros(n),
            xnew: DVector::zeros(n),
            hx: DVector::zeros(n),
            maxiter: 100,
            th_acceptstep: 0.1,
            th_grad: 1e-5,
        }
    }

    /// Solves with bounds `lb − u ≤ x ≤ ub − u` (the control increment of a knot at `u`),
    /// starting from `xinit` clamped to them.
    pub fn solve(
        &mut self,
        h: &DMatrix<f64>,
        q: &DVector<f64>,
        u: &DVector<f64>,
        u_lb: &DVector<f64>,
        u_ub: &DVector<f64>,
        xinit: &DVector<f64>,
    ) -> BoxQpResult {
        let n = self.x.len();
        let lb = |j: usize| u_lb[j] - u[j];
        let ub = |j: usize| u_ub[j] - u[j];
        for j in 0..n {
            self.x[j] = xinit[j].min(ub(j)).max(lb(j));
        }
        for _ in 0..self.maxiter {
            // 1. Gradient and active set.
            self.g.copy_from(q);
            self.g.gemv(1.0, h, &self.x, 1.0);
            self.free.clear();
            self.clamped.clear();
            for j in 0..n {
                let (gj, xj) = (self.g[j], self.x[j]);
                if (xj == lb(j) && gj > 0.0) || (xj == ub(j) && gj < 0.0) {
                    self.clamped.push(j);
                } else {
                    self.free.push(j);
                }
            }
            let nf = self.free.len();
            // 2. Newton step on the free set.
            for (a, &fi) in self.free.iter().enumerate() {
                let mut s = q[fi];
                for j in 0..n {
                    s += h[(fi, j)] * self.x[j];
                }
                self.qf[a] = s;
                for (b, &fj) in self.free.iter().enumerate() {
                    self.hff[(a, b)] = h[(fi, fj)];
                }
            }
            if !cholesky_inverse(&mut self.hff, &mut self.hff_inv, nf) {
                return BoxQpResult { ok: false };
            }
            self.dx.fill(0.0);
            for (a, &fi) in self.free.iter().enumerate() {
                let mut s = 0.0;
                for b in 0..nf {
                    s -= self.hff_inv[(a, b)] * self.qf[b];
                }
                self.dx[fi] = s;
                self.g[fi] = -self.qf[a];
            }
            // 3. Projected line search.
            let fold = objective(&mut self.hx, h, q, &self.x);
            let mut alpha = 1.0;
            for _ in 0..10 {
                for j in 0..n {
                    self.xnew[j] = (self.x[j] + alpha * self.dx[j]).min(ub(j)).max(lb(j));
                }
                let fnew = objective(&mut self.hx, h, q, &self.xnew);
                let mut descent = 0.0;
                for j in 0..n {
                    descent += self.g[j] * (self.x[j] - self.xnew[j]);
                }
                if fold - fnew > self.th_acceptstep * descent {
                    self.x.copy_from(&self.xnew);
                    break;
                }
                alpha *= 0.5;
            }
            // 4. Convergence on the free gradient.
            if self.qf.rows(0, nf).amax() <= self.th_grad {
                break;
            }
        }
        BoxQpResult { ok: true }
    }

    /// `K` with the rows of the free set `H_ff⁻¹ Q_xu,fᵀ` and zero rows for the clamped set.
    pub fn free_gains(&self, qxu: &DMatrix<f64>, kk: &mut DMatrix<f64>) {
        kk.fill(0.0);
        let nf = self.free.len();
        for (a, &fa) in self.free.iter().enumerate() {
            for c in 0..kk.ncols() {
                let mut s = 0.0;
                for b in 0..nf {
                    s += self.hff_inv[(a, b)] * qxu[(c, self.free[b])];
                }
                kk[(fa, c)] = s;
            }
        }
    }
}

/// `½ xᵀ H x + qᵀ x` (`hx` a buffer).
fn objective(hx: &mut DVector<f64>, h: &DMatrix<f64>, q: &DVector<f64>, x: &DVector<f64>) -> f64 {
    hx.gemv(1.0, h, x, 0.0);
    0.5 * x.dot(hx) + q.dot(x)
}

/// Factorises the leading `n × n` block of the symmetric `a` in place, `a = L Lᵀ` (`L` in the
/// lower triangle); `false` when it is not positive definite (`a` is then partly overwritten).
pub(crate) fn cholesky_in_place(a: &mut DMatrix<f64>, n: usize) -> bool {
    for j in 0..n {
        let mut d = a[(j, j)];
        for k in 0..j {
            d -= a[(j, k)] * a[(j, k)];
        }
        if d.is_nan() || d <= 0.0 {
            return false;
        }
        let d = d.sqrt();
        a[(j, j)] = d;
        for i in j + 1..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= a[(i, k)] * a[(j, k)];
            }
            a[(i, j)] = s / d;
        }
    }
    true
}

/// Solves `L Lᵀ x = b` in place for every column of `b`, with `L` from [`cholesky_in_place`].
pub(crate) fn cholesky_solve<
    C: nalgebra::Dim,
    S: nalgebra::RawStorageMut<f64, nalgebra::Dyn, C>,
>(
    l: &DMatrix<f64>,
    b: &mut nalgebra::Matrix<f64, nalgebra::Dyn, C, S>,
) {
    let n = l.nrows();
    for c in 0..b.ncols() {
        for i in 0..n {
            let mut s = b[(i, c)];
            for k in 0..i {
                s -= l[(i, k)] * b[(k, c)];
            }
            b[(i, c)] = s / l[(i, i)];
        }
        for i in (0..n).rev() {
            let mut s = b[(i, c)];
            for k in i + 1..n {
                s -= l[(k, i)] * b[(k, c)];
            }
            b[(i, c)] = s / l[(i, i)];
        }
    }
}

/// [`cholesky_solve`] for the right-hand sides stored as the rows of `bt` (`m × n`: column `i`
/// holds entry `i` of all `m` systems), vectorised across the systems. Each system takes
/// exactly the operations of [`cholesky_solve`] in its order (a multiply, then a subtract), so
/// the solutions are the same to the bit.
pub(crate) fn cholesky_solve_rows(l: &DMatrix<f64>, bt: &mut DMatrix<f64>) {
    let n = l.nrows();
    let m = bt.nrows();
    assert!(bt.ncols() == n, "cholesky_solve_rows: {} columns, expected {n}", bt.ncols());
    #[cfg(target_arch = "x86_64")]
    if is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked at run time).
        unsafe { solve_rows_avx2(l, bt.as_mut_slice(), m, n) };
        return;
    }
    solve_rows(l, bt.as_mut_slice(), m, n);
}

#[inline(always)]
fn solve_rows(l: &DMatrix<f64>, b: &mut [f64], m: usize, n: usize) {
    // Forward: column i -= L_ik column k (k < i), then /= L_ii.
    for i in 0..n {
        let (head, tail) = b.split_at_mut(i * m);
        let ci = &mut tail[..m];
        for k in 0..i {
            let lik = l[(i, k)];
            for (x, y) in ci.iter_mut().zip(&head[k * m..(k + 1) * m]) {
                *x -= lik * y;
            }
        }
        let d = l[(i, i)];
        ci.iter_mut().for_each(|x| *x /= d);
    }
    // Backward: column i -= L_ki column k (k > i), then /= L_ii.
    for i in (0..n).rev() {
        let (head, tail) = b.split_at_mut((i + 1) * m);
        let ci = &mut head[i * m..];
        for k in i + 1..n {
            let lki = l[(k, i)];
            let off = (k - i - 1) * m;
            for (x, y) in ci.iter_mut().zip(&tail[off..off + m]) {
                *x -= lki * y;
            }
        }
        let d = l[(i, i)];
        ci.iter_mut().for_each(|x| *x /= d);
    }
}

/// [`solve_rows`] compiled for AVX2 (no FMA: the multiply and the subtract stay two roundings).
///
/// # Safety
/// The CPU must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn solve_rows_avx2(l: &DMatrix<f64>, b: &mut [f64], m: usize, n: usize) {
    solve_rows(l, b, m, n);
}

/// The inverse of the leading `n × n` block of `a` (symmetric positive definite) into `inv`,
/// by an in-place Cholesky factorisation `a = L Lᵀ`; `false` when it is not positive definite.
fn cholesky_inverse(a: &mut DMatrix<f64>, inv: &mut DMatrix<f64>, n: usize) -> bool {
    if !cholesky_in_place(a, n) {
        return false;
    }
    // inv = L⁻ᵀ L⁻¹, column by column of the identity.
    for c in 0..n {
        for i in 0..n {
            let mut s = if i == c { 1.0 } else { 0.0 };
            for k in 0..i {
                s -= a[(i, k)] * inv[(k, c)];
            }
            inv[(i, c)] = s / a[(i, i)];
        }
        for i in (0..n).rev() {
            let mut s = inv[(i, c)];
            for k in i + 1..n {
                s -= a[(k, i)] * inv[(k, c)];
            }
            inv[(i, c)] = s / a[(i, i)];
        }
    }
    true
}
