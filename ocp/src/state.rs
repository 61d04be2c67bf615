//! The multibody state `x = (q, v)` on the configuration manifold (Crocoddyl's
//! `StateMultibody`), with `⊕` / `⊖` and their Jacobians.
//!
//! - `x ⊕ dx = (q ⊕ dq, v + dv)`, `dx = (dq, dv)` of length `ndx = 2 nv`;
//! - `x₁ ⊖ x₀ = (q₁ ⊖ q₀, v₁ − v₀)` (`diff(x0, x1)`, Crocoddyl's argument order), where a
//!   continuous joint's `q₁ ⊖ q₀` is the angle of the relative rotation in `(−π, π]` (its
//!   configuration space is the circle, as in Pinocchio), not sodyn's `q₁ − q₀`;
//! - Jacobians are block diagonal: the `q` block is sodyn's `d_integrate` / `d_difference`
//!   (tangent-space, joint by joint), the `v` block is `±I`.

use nalgebra::{DMatrix, DVector};
use sodyn::model::lie::Arg;
use sodyn::model::{JointType, Model};
use std::sync::Arc;

use crate::error::{OcpError, Result};

/// The state space of a multibody model.
#[derive(Clone, Debug)]
pub struct StateMultibody {
    model: Arc<Model>,
}

/// Scratch of one state operation (split `q`, `v` copies: sodyn's functions take whole vectors).
#[derive(Clone, Debug)]
pub struct StateScratch {
    pub(crate) q0: DVector<f64>,
    pub(crate) q1: DVector<f64>,
    pub(crate) dq: DVector<f64>,
    pub(crate) jq: DMatrix<f64>,
}

/// sodyn-ocp works on the full tree: a model in reduced coordinates (mimic joints) is refused.
///
/// # Errors
/// A reduced model.
pub(crate) fn check_not_reduced(model: &Model) -> Result<()> {
    if model.is_reduced() {
        return Err(OcpError::new(
            "the model has mimic joints in reduced coordinates (UrdfOptions { mimic: true }): \
             sodyn-ocp does not support them yet; load it without mimic",
        ));
    }
    Ok(())
}

impl StateMultibody {
    /// The state of `model`.
    pub fn new(model: Arc<Model>) -> Self {
        StateMultibody { model }
    }
    /// The model.
    pub fn model(&self) -> &Arc<Model> {
        &self.model
    }
    /// `nq + nv`.
    pub fn nx(&self) -> usize {
        self.model.nq() + self.model.nv()
    }
    /// `2 nv`.
    pub fn ndx(&self) -> usize {
        2 * self.model.nv()
    }
    /// `nq`.
    pub fn nq(&self) -> usize {
        self.model.nq()
    }
    /// `nv`.
    pub fn nv(&self) -> usize {
        self.model.nv()
    }
    /// A scratch for this state.
    pub fn scratch(&self) -> StateScratch {
        let (nq, nv) = (self.nq(), self.nv());
        StateScratch {
            q0: DVector::zeros(nq),
            q1: DVector::zeros(nq),
            dq: DVector::zeros(nv),
            jq: DMatrix::zeros(nv, nv),
        }
    }
    /// The neutral state `(q_neutral, 0)`.
    pub fn zero(&self) -> DVector<f64> {
        let mut x = DVector::zeros(self.nx());
        x.rows_mut(0, self.nq()).copy_from(&self.model.neutral());
        x
    }
    /// Checks the length and finiteness of a state and the norm of its quaternions.
    ///
    /// # Errors
    /// [`OcpError`] naming `what`.
    pub fn check_x(&self, what: &str, x: &DVector<f64>) -> Result<()> {
        if x.len() != self.nx() {
            return Err(OcpError::new(format!(
                "{what}: length {} (expected nx = {})",
                x.len(),
                self.nx()
            )));
        }
        if let Some(i) = x.iter().position(|v| !v.is_finite()) {
            return Err(OcpError::new(format!("{what}: entry {i} is {}", x[i])));
        }
        let q = x.rows(0, self.nq()).into_owned();
        self.model.check_q(&q).map_err(|e| OcpError::new(format!("{what}: {e}")))
    }
    /// `out = x ⊕ dx`.
    pub fn integrate(&self, x: &DVector<f64>, dx: &DVector<f64>, out: &mut DVector<f64>) {
        let m = &*self.model;
        let (nq, nv) = (m.nq(), m.nv());
        let (xs, dxs, os) = (x.as_slice(), dx.as_slice(), out.as_mut_slice());
        for i in 1..m.njoints() {
            let (a, n, b, k) = (m.idx_q()[i], m.nqs()[i], m.idx_v()[i], m.nvs()[i]);
            m.joints()[i].integrate(&xs[a..a + n], &dxs[b..b + k], &mut os[a..a + n]);
        }
        for j in 0..nv {
            os[nq + j] = xs[nq + j] + dxs[nv + j];
        }
    }
    /// `out = x1 ⊖ x0`.
    pub fn diff(&self, x0: &DVector<f64>, x1: &DVector<f64>, out: &mut DVector<f64>) {
        let m = &*self.model;
        let (nq, nv) = (m.nq(), m.nv());
        let (a, b, o) = (x0.as_slice(), x1.as_slice(), out.as_mut_slice());
        for i in 1..m.njoints() {
            let (qa, n, vb, k) = (m.idx_q()[i], m.nqs()[i], m.idx_v()[i], m.nvs()[i]);
            m.joints()[i].difference(&a[qa..qa + n], &b[qa..qa + n], &mut o[vb..vb + k]);
            if let JointType::Continuous { .. } = m.joints()[i] {
                // A continuous joint's configuration space is the circle (Pinocchio's and
                // Crocoddyl's unbounded revolute joints): the difference is the angle of the
                // relative rotation, in (−π, π].
                let d = o[vb];
                o[vb] = d.sin().atan2(d.cos());
            }
        }
        for j in 0..nv {
            o[nv + j] = b[nq + j] - a[nq + j];
        }
    }
    /// The `q` block `∂(q ⊕ dq)/∂q` or `∂(q ⊕ dq)/∂dq` (`arg`) into `sc.jq`.
    pub(crate) fn jintegrate_q(
        &self,
        sc: &mut StateScratch,
        x: &DVector<f64>,
        dx: &DVector<f64>,
        arg: Arg,
    ) -> Result<()> {
        let (nq, nv) = (self.nq(), self.nv());
        sc.q0.copy_from(&x.rows(0, nq));
        sc.dq.copy_from(&dx.rows(0, nv));
        // An error here is a non-finite increment (dynamics that overflowed).
        self.model
            .d_integrate_blocks_into(&sc.q0, &sc.dq, arg, &mut sc.jq)
            .map_err(|e| OcpError::new(format!("the integrator's increment: {e}")))
    }
    /// `∂(x ⊕ dx)/∂x` (`arg = Arg::First`) or `∂(x ⊕ dx)/∂dx` (`Arg::Second`), `ndx × ndx`,
    /// into `out`: `blockdiag(∂(q ⊕ dq)/∂·, I)` (Crocoddyl's `Jintegrate`).
    ///
    /// # Errors
    /// A non-finite `dx`.
    pub fn jintegrate(
        &self,
        sc: &mut StateScratch,
        x: &DVector<f64>,
        dx: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) -> Result<()> {
        let nv = self.nv();
        self.jintegrate_q(sc, x, dx, arg)?;
        out.fill(0.0);
        out.view_mut((0, 0), (nv, nv)).copy_from(&sc.jq);
        out.view_mut((nv, nv), (nv, nv)).fill_diagonal(1.0);
        Ok(())
    }
    /// The `q` block `∂(q1 ⊖ q0)/∂q0` or `/∂q1` (`arg`) into `sc.jq`.
    pub(crate) fn jdiff_q(
        &self,
        sc: &mut StateScratch,
        x0: &DVector<f64>,
        x1: &DVector<f64>,
        arg: Arg,
    ) {
        let nq = self.nq();
        sc.q0.copy_from(&x0.rows(0, nq));
        sc.q1.copy_from(&x1.rows(0, nq));
        // `sc.jq` was zeroed at creation, and every call writes the same diagonal blocks.
        self.model
            .d_difference_blocks_into(&sc.q0, &sc.q1, arg, &mut sc.jq)
            .expect("d_difference_blocks_into on checked dimensions");
    }
    /// `∂(x1 ⊖ x0)/∂x0` (`arg = Arg::First`) or `∂(x1 ⊖ x0)/∂x1` (`Arg::Second`), `ndx × ndx`,
    /// into `out`: `blockdiag(∂(q1 ⊖ q0)/∂q, ∓I)`.
    pub fn jdiff(
        &self,
        sc: &mut StateScratch,
        x0: &DVector<f64>,
        x1: &DVector<f64>,
        arg: Arg,
        out: &mut DMatrix<f64>,
    ) {
        let nv = self.nv();
        self.jdiff_q(sc, x0, x1, arg);
        out.fill(0.0);
        out.view_mut((0, 0), (nv, nv)).copy_from(&sc.jq);
        let sign = if arg == Arg::First { -1.0 } else { 1.0 };
        out.view_mut((nv, nv), (nv, nv)).fill_diagonal(sign);
    }
}
