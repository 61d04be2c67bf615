//! Quasi-static controls (Crocoddyl's `quasiStatic`): the control that holds a state at rest.
//!
//! With `g(q) = RNEA(q, 0, 0)`, `S` the actuation matrix and `J_c` the active contacts'
//! Jacobian: `[S J_cᵀ] [u; λ] = g(q)` in the least-squares, least-norm sense
//! (Moore-Penrose pseudo-inverse), and `u` its control rows. The contact Jacobian comes from
//! the knot's KKT workspace, with the knot's damping.

use nalgebra::{DMatrix, DVector};
use sodyn::algo::{Data, rnea};
use sodyn::deriv::{ContactData, kkt_dynamics};

use crate::action::{ActionKind, ActionModel};
use crate::error::{OcpError, Result};

pub(crate) fn quasi_static(m: &ActionModel, x: &DVector<f64>) -> Result<DVector<f64>> {
    let model = m.model();
    let (nq, nv, nu) = (model.nq(), model.nv(), m.nu());
    if nu == 0 {
        return Ok(DVector::zeros(0));
    }
    let q = x.rows(0, nq).into_owned();
    let zero = DVector::zeros(nv);
    let mut data = Data::new(model);
    let g = rnea(model, &mut data, &q, &zero, &zero, None)?.clone();
    let (active, damping): (Vec<_>, f64) = match &m.kind {
        ActionKind::Euler { contacts, damping, .. }
        | ActionKind::RungeKutta { contacts, damping, .. } => {
            (contacts.iter().filter(|c| c.active).map(|c| c.contact.clone()).collect(), *damping)
        }
        ActionKind::Impulse { .. } => (Vec::new(), 0.0),
    };
    let nc: usize = active.iter().map(|c| c.dim()).sum();
    let mut a = DMatrix::zeros(nv, nu + nc);
    let off = nv - nu;
    for j in 0..nu {
        a[(off + j, j)] = 1.0;
    }
    if nc > 0 {
        let mut cd = ContactData::new(model, &active)?;
        // The knot's damping, as its dynamics uses it: a redundant contact set that the
        // knot regularises is accepted here too (only the Jacobian is used).
        if damping > 0.0 {
            cd.set_damping(damping)?;
        }
        kkt_dynamics(model, &mut data, &mut cd, &q, &zero, &zero)?;
        a.columns_mut(nu, nc).copy_from(&cd.jac().transpose());
    }
    let pinv = a.pseudo_inverse(1e-12).map_err(|e| OcpError::new(format!("quasi_static: {e}")))?;
    Ok((pinv * g).rows(0, nu).into_owned())
}
