//! Action models: one knot of a shooting problem (Crocoddyl's `ActionModelAbstract`).
//!
//! Inputs: the state `x = (q, v)`, the control `u`. Outputs ([`ActionData`]): the next state
//! `x′ = f(x, u)`, the cost `ℓ(x, u)`, and with [`ActionModel::calc_diff`] the Jacobians
//! `F_x`, `F_u` (tangent space) and the Gauss-Newton cost derivatives `ℓ_x, ℓ_u, ℓ_xx, ℓ_xu,
//! ℓ_uu`.
//!
//! Kinds:
//! 1. [`ActionKind::Euler`]: differential dynamics `a = FD(q, v, τ)` (free: ABA; contact: the
//!    KKT dynamics of [`sodyn::deriv::kkt_dynamics`]) with `τ` from the actuation, integrated by
//!    symplectic Euler (Crocoddyl's `IntegratedActionModelEuler`):
//!    `v′ = v + dt a`, `q′ = q ⊕ dt v′`, `ℓ = dt ℓ_c(x, u)`;
//!    - `F_x = ∂(x ⊕ δ)/∂x + ∂(x ⊕ δ)/∂δ ∂δ/∂x` with `δ = (dt v + dt² a, dt a)`;
//!    - a node without control (the terminal node) has no dynamics: `x′ = x`, `ℓ = ℓ_c(x)`.
//! 2. [`ActionKind::Impulse`]: impulse dynamics at a contact switch (Crocoddyl's
//!    `ActionModelImpulseFwdDynamics`): `x′ = (q, v⁺)`, `v⁺` from
//!    [`sodyn::deriv::impact_dynamics`], `ℓ = ℓ_c(x)` with the impulses as contact forces; no
//!    control.

use nalgebra::{DMatrix, DVector, Matrix6};
use sodyn::algo::{Data, aba};
use sodyn::deriv::{
    ContactData, fd_derivatives, fd_so_contracted, impact_derivatives, impact_dynamics,
    impact_so_contracted, kkt_derivatives, kkt_dynamics, kkt_so_contracted,
};
use sodyn::model::lie::Arg;
use sodyn::model::{Contact, JointType, Model};

use crate::cost::{CostData, CostDerivs, CostModelSum, CurvatureWork};
use crate::curvature::{Group, bracket_form, djr_t};
use crate::error::{OcpError, Result};
use crate::linalg::gemm_nn;
use crate::residual::NodeView;
use crate::state::{StateMultibody, StateScratch};

/// How the control enters the joint torques.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Actuation {
    /// `τ = u` (`nu = nv`): Crocoddyl's `ActuationModelFull`.
    Full,
    /// `τ = (0₆, u)` (`nu = nv − 6`; the root free flyer is unactuated): Crocoddyl's
    /// `ActuationModelFloatingBase`.
    FloatingBase,
}

impl Actuation {
    /// The control dimension on `model`.
    pub fn nu(&self, model: &Model) -> usize {
        match self {
            Actuation::Full => model.nv(),
            Actuation::FloatingBase => model.nv() - 6,
        }
    }
    /// The first actuated velocity index.
    fn offset(&self) -> usize {
        match self {
            Actuation::Full => 0,
            Actuation::FloatingBase => 6,
        }
    }
    /// Checks the actuation against the model.
    pub fn check(&self, model: &Model) -> Result<()> {
        if *self == Actuation::FloatingBase
            && (model.njoints() < 2 || model.joints()[1] != JointType::FreeFlyer)
        {
            return Err(OcpError::new(
                "ActuationModelFloatingBase: the model's first joint is not a free flyer",
            ));
        }
        Ok(())
    }
}

/// A named contact of a contact set; inactive contacts are kept but do not constrain.
#[derive(Clone, Debug, PartialEq)]
pub struct NamedContact {
    /// The name (unique in the set).
    pub name: String,
    /// The contact.
    pub contact: Contact,
    /// Whether it constrains the dynamics.
    pub active: bool,
}

/// The dynamics of a knot.
#[derive(Clone, Debug, PartialEq)]
pub enum ActionKind {
    /// Differential dynamics integrated by symplectic Euler over `dt`.
    Euler {
        /// The time step (`0` for a terminal node).
        dt: f64,
        /// The contacts (empty: free dynamics, ABA).
        contacts: Vec<NamedContact>,
        /// Damping of the Delassus solve (Crocoddyl's `JMinvJt_damping`; 0: exact).
        damping: f64,
    },
    /// Impulse dynamics at a contact switch.
    Impulse {
        /// The impulse contacts.
        contacts: Vec<NamedContact>,
        /// The coefficient of restitution.
        restitution: f64,
        /// Damping of the Delassus solve.
        damping: f64,
    },
}

/// One knot: state, actuation, dynamics, costs, control bounds.
#[derive(Clone, Debug)]
pub struct ActionModel {
    /// The state space.
    pub state: StateMultibody,
    /// The actuation.
    pub actuation: Actuation,
    /// The dynamics.
    pub kind: ActionKind,
    /// The costs.
    pub costs: CostModelSum,
    /// Control lower bounds (box-FDDP), length `nu`.
    pub u_lb: DVector<f64>,
    /// Control upper bounds.
    pub u_ub: DVector<f64>,
}

/// Per-knot results and workspace.
#[derive(Clone, Debug)]
pub struct ActionData {
    /// `x′`.
    pub xnext: DVector<f64>,
    /// `ℓ`.
    pub cost: f64,
    /// `∂x′/∂x` (`ndx × ndx`).
    pub fx: DMatrix<f64>,
    /// `∂x′/∂u` (`ndx × nu`).
    pub fu: DMatrix<f64>,
    /// `ℓ_x`.
    pub lx: DVector<f64>,
    /// `ℓ_u`.
    pub lu: DVector<f64>,
    /// `ℓ_xx`.
    pub lxx: DMatrix<f64>,
    /// `ℓ_xu`.
    pub lxu: DMatrix<f64>,
    /// `ℓ_uu`.
    pub luu: DMatrix<f64>,
    /// The joint accelerations (Euler) or `v⁺` (impulse).
    pub a: DVector<f64>,
    /// The stacked contact forces (impulses at an impulse node) of the active contacts.
    pub lambda: DVector<f64>,
    /// `∂λ/∂x`.
    pub dlambda_dx: DMatrix<f64>,
    /// `∂λ/∂u`.
    pub dlambda_du: DMatrix<f64>,
    /// The cost terms' data.
    pub costs: CostData,
    q: DVector<f64>,
    v: DVector<f64>,
    tau: DVector<f64>,
    dx: DVector<f64>,
    da_dx: DMatrix<f64>,
    da_du: DMatrix<f64>,
    jq_x: DMatrix<f64>,
    jq_dx: DMatrix<f64>,
    data: Data,
    /// The active contact set's data (KKT or impact, with contracted capacity).
    contacts: Option<ContactData>,
    sc: StateScratch,
    /// The second-order term of the last [`ActionModel::second_order`]: the Hessian of
    /// `V′ₓᵀ (f(x ⊕ δx, u + δu) ⊖ f(x, u))` plus the residual curvature of the costs, in
    /// `z = (δx, δu)` (`(ndx + nu)²`); the exact Hessian of the knot's term in the Q-function is
    /// the Gauss-Newton `[ℓ_xx ℓ_xu; ℓ_ux ℓ_uu]` plus this.
    pub hzz: DMatrix<f64>,
    /// How many cost terms of the last [`ActionModel::second_order`] kept their Gauss-Newton
    /// Hessian (0: every residual has its exact curvature).
    pub gauss_newton_terms: usize,
    so: SoWork,
}

/// Buffers of [`ActionModel::second_order`].
#[derive(Clone, Debug)]
struct SoWork {
    w_a: DVector<f64>,
    w_lambda: DVector<f64>,
    groups: Vec<(usize, Group)>,
    planar: Option<String>,
    cost: CurvatureWork,
    e: DMatrix<f64>,
    ne: DMatrix<f64>,
    se: DMatrix<f64>,
    m6: [Matrix6<f64>; 3],
}

/// The velocity offset and group of every joint whose `⊕` is not affine, and the first planar
/// joint (whose second order is not implemented), if any.
fn lie_groups(m: &Model) -> (Vec<(usize, Group)>, Option<String>) {
    let (mut g, mut planar) = (Vec::new(), None);
    for i in 1..m.njoints() {
        match m.joints()[i] {
            JointType::FreeFlyer => g.push((m.idx_v()[i], Group::Se3)),
            JointType::Spherical => g.push((m.idx_v()[i], Group::So3)),
            JointType::Planar => planar = planar.or(Some(m.names()[i].clone())),
            _ => {}
        }
    }
    (g, planar)
}

fn active_contacts(contacts: &[NamedContact]) -> Vec<Contact> {
    contacts.iter().filter(|c| c.active).map(|c| c.contact.clone()).collect()
}

impl ActionModel {
    /// The model.
    pub fn model(&self) -> &Model {
        self.state.model()
    }
    /// The control dimension (0 at an impulse node).
    pub fn nu(&self) -> usize {
        match self.kind {
            ActionKind::Euler { .. } => self.actuation.nu(self.model()),
            ActionKind::Impulse { .. } => 0,
        }
    }
    /// The contacts of the knot.
    pub fn contacts(&self) -> &[NamedContact] {
        match &self.kind {
            ActionKind::Euler { contacts, .. } | ActionKind::Impulse { contacts, .. } => contacts,
        }
    }
    /// The row offset of contact `name` among the active contacts' stacked forces.
    pub fn contact_rows(&self, name: &str) -> Option<(Option<usize>, usize)> {
        let mut off = 0;
        for c in self.contacts() {
            if c.name == name {
                return Some((c.active.then_some(off), c.contact.dim()));
            }
            if c.active {
                off += c.contact.dim();
            }
        }
        None
    }
    /// Buffers for this knot.
    ///
    /// # Errors
    /// A rank-deficient or otherwise invalid active contact set; a model in reduced coordinates
    /// (mimic joints).
    pub fn create_data(&self) -> Result<ActionData> {
        let m = self.model();
        crate::state::check_not_reduced(m)?;
        let (nv, nu, ndx) = (m.nv(), self.nu(), self.state.ndx());
        let active = active_contacts(self.contacts());
        let nc: usize = active.iter().map(|c| c.dim()).sum();
        let mut contacts = None;
        if !active.is_empty() {
            let mut cd = ContactData::with_contracted(m, &active)?;
            let damping = match &self.kind {
                ActionKind::Euler { damping, .. } => *damping,
                ActionKind::Impulse { restitution, damping, .. } => {
                    cd.set_restitution(*restitution)?;
                    *damping
                }
            };
            if damping > 0.0 {
                cd.set_damping(damping)?;
            }
            contacts = Some(cd);
        }
        let mut fx = DMatrix::identity(ndx, ndx);
        fx.fill_diagonal(1.0);
        let (groups, planar) = lie_groups(m);
        let nz = ndx + nu;
        let so = SoWork {
            w_a: DVector::zeros(nv),
            w_lambda: DVector::zeros(nc),
            groups,
            planar,
            cost: CurvatureWork::new(m),
            e: DMatrix::zeros(6, nz),
            ne: DMatrix::zeros(6, nz),
            se: DMatrix::zeros(6, nz),
            m6: [Matrix6::zeros(); 3],
        };
        Ok(ActionData {
            hzz: DMatrix::zeros(nz, nz),
            gauss_newton_terms: 0,
            so,
            xnext: DVector::zeros(self.state.nx()),
            cost: 0.0,
            fx,
            fu: DMatrix::zeros(ndx, nu),
            lx: DVector::zeros(ndx),
            lu: DVector::zeros(nu),
            lxx: DMatrix::zeros(ndx, ndx),
            lxu: DMatrix::zeros(ndx, nu),
            luu: DMatrix::zeros(nu, nu),
            a: DVector::zeros(nv),
            lambda: DVector::zeros(nc),
            dlambda_dx: DMatrix::zeros(nc, ndx),
            dlambda_du: DMatrix::zeros(nc, nu),
            costs: self.costs.create_data(nv, nu),
            q: DVector::zeros(m.nq()),
            v: DVector::zeros(nv),
            tau: DVector::zeros(nv),
            dx: DVector::zeros(ndx),
            da_dx: DMatrix::zeros(nv, ndx),
            da_du: DMatrix::zeros(nv, nu),
            jq_x: DMatrix::zeros(nv, nv),
            jq_dx: DMatrix::zeros(nv, nv),
            data: Data::with_contracted(m),
            contacts,
            sc: self.state.scratch(),
        })
    }

    /// Next state and cost at `(x, u)`; `u = None` is Crocoddyl's `calc(x)` (the terminal node,
    /// or a knot without control).
    ///
    /// # Errors
    /// A singular mass matrix or contact set at this state.
    pub fn calc(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: Option<&DVector<f64>>,
    ) -> Result<()> {
        self.eval(d, x, u, false)
    }

    /// [`ActionModel::calc`] and the derivatives at `(x, u)`.
    ///
    /// # Errors
    /// As [`ActionModel::calc`].
    pub fn calc_diff(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: Option<&DVector<f64>>,
    ) -> Result<()> {
        self.eval(d, x, u, true)
    }

    fn eval(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: Option<&DVector<f64>>,
        diff: bool,
    ) -> Result<()> {
        let m = self.state.model().clone();
        let m = &*m;
        let (nq, nv) = (m.nq(), m.nv());
        d.q.copy_from(&x.rows(0, nq));
        d.v.copy_from(&x.rows(nq, nv));
        let zero_u = DVector::zeros(0);
        let with_dynamics;
        let mut cost_scale = 1.0;
        match &self.kind {
            ActionKind::Euler { dt, .. } => {
                let Some(u) = u else {
                    // No control: no dynamics (Crocoddyl's terminal calc(x)).
                    d.xnext.copy_from(x);
                    d.a.fill(0.0);
                    if diff {
                        d.fx.fill(0.0);
                        d.fx.fill_diagonal(1.0);
                    }
                    return self.eval_costs(d, x, &zero_u, false, diff, 1.0);
                };
                let dt = *dt;
                cost_scale = dt;
                let off = self.actuation.offset();
                d.tau.fill(0.0);
                d.tau.rows_mut(off, u.len()).copy_from(u);
                self.forward_dynamics(m, d, diff)?;
                // δ = (dt v + dt² a, dt a)  (symplectic Euler)
                for j in 0..nv {
                    d.dx[j] = dt * d.v[j] + dt * dt * d.a[j];
                    d.dx[nv + j] = dt * d.a[j];
                }
                self.state.integrate(x, &d.dx, &mut d.xnext);
                if diff {
                    self.euler_jacobians(d, x, dt)?;
                }
                with_dynamics = true;
                self.eval_costs(d, x, u, with_dynamics, diff, cost_scale)
            }
            ActionKind::Impulse { .. } => {
                self.impulse_dynamics(m, d, diff)?;
                d.xnext.rows_mut(0, nq).copy_from(&d.q);
                d.xnext.rows_mut(nq, nv).copy_from(&d.a);
                if diff {
                    // x′ = (q, v⁺): F_x = [I 0; ∂v⁺/∂q ∂v⁺/∂v⁻].
                    d.fx.fill(0.0);
                    for j in 0..nv {
                        d.fx[(j, j)] = 1.0;
                    }
                    d.fx.view_mut((nv, 0), (nv, 2 * nv)).copy_from(&d.da_dx);
                }
                self.eval_costs(d, x, &zero_u, true, diff, cost_scale)
            }
        }
    }

    /// The second-order term of the knot into `d.hzz` (see [`ActionData::hzz`]), with `vx_next`
    /// the gradient `V′ₓ` of the value function at the next node (`ndx`), after
    /// [`ActionModel::calc_diff`] at the same `(x, u)`.
    ///
    /// Inputs: `λ = (λ_q, λ_v) = V′ₓ`, the knot's first-order terms. Outputs (`z = (δq, δv, δu)`):
    /// 1. Euler, `a = FD(q, v, τ)` or the KKT dynamics, `Δ = dt v′ = dt v + dt² a`:
    ///    - the weight on `a`: `w_a = dt λ_v + dt² J_Δᵀ λ_q` (`J_Δ = ∂(q ⊕ Δ)/∂Δ`), and on the
    ///      contact forces the costs' `w_λ` ([`CostModelSum`]);
    ///    - `C = ∂²(w_aᵀ a + w_λᵀ λ)/∂(q, v, τ)²` contracted, no `nv³` tensor
    ///      ([`sodyn::deriv::fd_so_contracted`], [`sodyn::deriv::kkt_so_contracted`]): `H_qq +=
    ///      sym(C_qq)` (the nested tangent derivative's symmetric part is the Hessian),
    ///      `H_qv += C_qv`, `H_vv += C_vv`, `H_qu += C_τq` (actuated columns);
    ///    - the integrator's curvature per free-flyer or spherical joint (`ocp/src/curvature.rs`):
    ///      with `E = ∂ε/∂z = dt [∂v′/∂x, ∂v′/∂u]` (the joint's rows), `H += E_qᵀ N E + Eᵀ Nᵀ E_q
    ///      + Eᵀ sym(K) E`;
    /// 2. impulse, `x′ = (q, v⁺)`: `C` of `λ_vᵀ v⁺ + w_λᵀ Λ`
    ///    ([`sodyn::deriv::impact_so_contracted`]): `H_qq += sym(C_qq)`, `H_qv += C_qv⁻`;
    /// 3. every knot: the costs' residual curvature (times `dt` on an Euler knot).
    ///
    /// # Errors
    /// `vx_next` or `x` of the wrong length, `vx_next` not finite, data of another knot; a planar
    /// joint; the dynamics' errors.
    pub fn second_order(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: Option<&DVector<f64>>,
        vx_next: &DVector<f64>,
    ) -> Result<()> {
        let m = self.state.model().clone();
        let m = &*m;
        let (nv, ndx) = (m.nv(), self.state.ndx());
        if vx_next.len() != ndx {
            return Err(OcpError::new(format!(
                "second_order: vx_next has length {}, expected ndx = {ndx}",
                vx_next.len()
            )));
        }
        if let Some(i) = vx_next.iter().position(|v| !v.is_finite()) {
            return Err(OcpError::new(format!("second_order: vx_next[{i}] is {}", vx_next[i])));
        }
        if d.hzz.nrows() != ndx + self.nu() || d.a.len() != nv || x.len() != self.state.nx() {
            return Err(OcpError::new(format!(
                "second_order: x has length {} (expected nx = {}) or the data was made for \
                 another knot (make it with this knot's create_data)",
                x.len(),
                self.state.nx()
            )));
        }
        if let Some(j) = &d.so.planar {
            return Err(OcpError::new(format!(
                "joint '{j}': the second order of a planar joint's integrator is not implemented"
            )));
        }
        d.hzz.fill(0.0);
        d.so.w_lambda.fill(0.0);
        let zero_u = DVector::zeros(0);
        let (dt, dynamics) = match (&self.kind, u) {
            (ActionKind::Euler { dt, .. }, Some(_)) => (*dt, true),
            (ActionKind::Euler { .. }, None) => (1.0, false),
            (ActionKind::Impulse { .. }, _) => (1.0, true),
        };
        // 3. The costs' curvature (and their weight on the forces).
        {
            let with_u = dynamics && matches!(self.kind, ActionKind::Euler { .. });
            let forces = dynamics.then_some((&d.lambda, &d.dlambda_dx, &d.dlambda_du));
            let mut view = NodeView {
                model: self.state.model(),
                state: &self.state,
                data: &mut d.data,
                sc: &mut d.sc,
                x,
                q: &d.q,
                v: &d.v,
                u: u.unwrap_or(&zero_u),
                forces,
            };
            d.gauss_newton_terms = self.costs.curvature(
                &d.costs,
                &mut view,
                &d.so.groups,
                dt,
                &mut d.hzz,
                &mut d.so.w_lambda,
                &mut d.so.cost,
                with_u || dynamics,
            )?;
        }
        if !dynamics {
            return Ok(());
        }
        let (lq, lv) = (vx_next.rows(0, nv), vx_next.rows(nv, nv));
        let so = &mut d.so;
        let h = &mut d.hzz;
        match &self.kind {
            ActionKind::Euler { .. } => {
                // 1. w_a = dt λ_v + dt² J_Δᵀ λ_q.
                so.w_a.copy_from(&lv);
                so.w_a *= dt;
                so.w_a.gemv_tr(dt * dt, &d.jq_dx, &lq, 1.0);
                let (off, nu) = (self.actuation.offset(), self.nu());
                let (cqq, cqv, cvv, ctq) = match d.contacts.as_mut() {
                    Some(cd) => {
                        let kc = kkt_so_contracted(
                            m,
                            &mut d.data,
                            cd,
                            &d.q,
                            &d.v,
                            &d.tau,
                            &so.w_a,
                            &so.w_lambda,
                        )?;
                        (kc.c_qq(), kc.c_qv(), kc.c_vv(), kc.c_tauq())
                    }
                    None => {
                        let c = fd_so_contracted(m, &mut d.data, &d.q, &d.v, &d.tau, &so.w_a)?;
                        (c.c_qq(), c.c_qv(), c.c_vv(), c.c_tauq())
                    }
                };
                for j in 0..nv {
                    for k in 0..nv {
                        h[(j, k)] += 0.5 * (cqq[(j, k)] + cqq[(k, j)]);
                        h[(j, nv + k)] += cqv[(j, k)];
                        h[(nv + k, j)] += cqv[(j, k)];
                        h[(nv + j, nv + k)] += 0.5 * (cvv[(j, k)] + cvv[(k, j)]);
                    }
                }
                // H_qu: C_τq[(off + i, k)] = ∂/∂q_k (∂(wᵀy)/∂τ_{off+i}).
                for i in 0..nu {
                    for k in 0..nv {
                        let c = ctq[(off + i, k)];
                        h[(k, ndx + i)] += c;
                        h[(ndx + i, k)] += c;
                    }
                }
                // The integrator's curvature per Lie joint.
                let nz = h.nrows();
                for &(b, g) in &so.groups {
                    let n = g.dim();
                    let [a, bl, t] = &mut so.m6;
                    let mut lam = [0.0; 6];
                    let mut del = [0.0; 6];
                    for i in 0..n {
                        lam[i] = lq[b + i];
                        del[i] = d.dx[b + i];
                    }
                    // N = ½ Adᵀ B_λ J_Δ (into `t`).
                    a.fill(0.0);
                    for i in 0..n {
                        for j in 0..n {
                            a[(i, j)] = d.jq_x[(b + i, b + j)];
                        }
                    }
                    bracket_form(g, &lam[..n], bl);
                    let mut jr = Matrix6::zeros();
                    for i in 0..n {
                        for j in 0..n {
                            jr[(i, j)] = d.jq_dx[(b + i, b + j)];
                        }
                    }
                    *t = a.transpose() * *bl * jr * 0.5;
                    // K: column j = (∂J_Δ/∂Δ_j)ᵀ λ (into `a`; sym below).
                    djr_t(g, &del[..n], &lam[..n], a);
                    // E = dt [∂v′/∂x, ∂v′/∂u] (the joint's rows).
                    for i in 0..n {
                        for c in 0..ndx {
                            so.e[(i, c)] = dt * d.fx[(nv + b + i, c)];
                        }
                        for c in 0..nu {
                            so.e[(i, ndx + c)] = dt * d.fu[(nv + b + i, c)];
                        }
                    }
                    // N E and sym(K) E.
                    for i in 0..n {
                        for c in 0..nz {
                            let (mut ne, mut se) = (0.0, 0.0);
                            for r in 0..n {
                                ne += t[(i, r)] * so.e[(r, c)];
                                se += 0.5 * (a[(i, r)] + a[(r, i)]) * so.e[(r, c)];
                            }
                            so.ne[(i, c)] = ne;
                            so.se[(i, c)] = se;
                        }
                    }
                    for i in 0..n {
                        for c in 0..nz {
                            h[(b + i, c)] += so.ne[(i, c)];
                            h[(c, b + i)] += so.ne[(i, c)];
                        }
                    }
                    for r in 0..nz {
                        for c in 0..nz {
                            let mut x = 0.0;
                            for i in 0..n {
                                x += so.e[(i, r)] * so.se[(i, c)];
                            }
                            h[(r, c)] += x;
                        }
                    }
                }
            }
            ActionKind::Impulse { .. } => {
                if let Some(cd) = d.contacts.as_mut() {
                    so.w_a.copy_from(&lv);
                    let ic = impact_so_contracted(
                        m,
                        &mut d.data,
                        cd,
                        &d.q,
                        &d.v,
                        &so.w_a,
                        &so.w_lambda,
                    )?;
                    let (cqq, cqv) = (ic.c_qq(), ic.c_qvminus());
                    for j in 0..nv {
                        for k in 0..nv {
                            h[(j, k)] += 0.5 * (cqq[(j, k)] + cqq[(k, j)]);
                            h[(j, nv + k)] += cqv[(j, k)];
                            h[(nv + k, j)] += cqv[(j, k)];
                        }
                    }
                }
            }
        }
        Ok(())
    }

    /// `a = FD(q, v, τ)` (and `∂a/∂x`, `∂a/∂u`, `λ` and its derivatives with contacts).
    fn forward_dynamics(&self, m: &Model, d: &mut ActionData, diff: bool) -> Result<()> {
        let (nv, nu, off) = (m.nv(), self.nu(), self.actuation.offset());
        match d.contacts.as_mut() {
            None => {
                if diff {
                    fd_derivatives(m, &mut d.data, &d.q, &d.v, &d.tau, None)?;
                    d.a.copy_from(d.data.qdd());
                    d.da_dx.view_mut((0, 0), (nv, nv)).copy_from(d.data.dqdd_dq());
                    d.da_dx.view_mut((0, nv), (nv, nv)).copy_from(d.data.dqdd_dv());
                    d.da_du.copy_from(&d.data.minv().columns(off, nu));
                } else {
                    let a = aba(m, &mut d.data, &d.q, &d.v, &d.tau, None)?;
                    d.a.copy_from(a);
                }
            }
            Some(cd) => {
                let k = if diff {
                    let k = kkt_derivatives(m, &mut d.data, cd, &d.q, &d.v, &d.tau)?;
                    d.da_dx.view_mut((0, 0), (nv, nv)).copy_from(k.dqdd_dq());
                    d.da_dx.view_mut((0, nv), (nv, nv)).copy_from(k.dqdd_dv());
                    d.da_du.copy_from(&k.dqdd_dtau().columns(off, nu));
                    let nc = d.lambda.len();
                    d.dlambda_dx.view_mut((0, 0), (nc, nv)).copy_from(k.dlambda_dq());
                    d.dlambda_dx.view_mut((0, nv), (nc, nv)).copy_from(k.dlambda_dv());
                    d.dlambda_du.copy_from(&k.dlambda_dtau().columns(off, nu));
                    k
                } else {
                    kkt_dynamics(m, &mut d.data, cd, &d.q, &d.v, &d.tau)?
                };
                d.a.copy_from(k.qdd());
                d.lambda.copy_from(k.lambda());
            }
        }
        Ok(())
    }

    /// `v⁺` into `d.a`, the impulses into `d.lambda` (and their derivatives).
    fn impulse_dynamics(&self, m: &Model, d: &mut ActionData, diff: bool) -> Result<()> {
        let nv = m.nv();
        match d.contacts.as_mut() {
            None => {
                d.a.copy_from(&d.v);
                if diff {
                    d.da_dx.fill(0.0);
                    for j in 0..nv {
                        d.da_dx[(j, nv + j)] = 1.0;
                    }
                }
            }
            Some(cd) => {
                let im = if diff {
                    let im = impact_derivatives(m, &mut d.data, cd, &d.q, &d.v)?;
                    d.da_dx.view_mut((0, 0), (nv, nv)).copy_from(im.dvplus_dq());
                    d.da_dx.view_mut((0, nv), (nv, nv)).copy_from(im.dvplus_dvminus());
                    let nc = d.lambda.len();
                    d.dlambda_dx.view_mut((0, 0), (nc, nv)).copy_from(im.dimpulse_dq());
                    d.dlambda_dx.view_mut((0, nv), (nc, nv)).copy_from(im.dimpulse_dvminus());
                    im
                } else {
                    impact_dynamics(m, &mut d.data, cd, &d.q, &d.v)?
                };
                d.a.copy_from(im.vplus());
                d.lambda.copy_from(im.impulse());
            }
        }
        Ok(())
    }

    /// `F_x`, `F_u` of symplectic Euler from `∂a/∂x`, `∂a/∂u`:
    /// - `∂δ/∂x = (dt² a_x + dt [0 I], dt a_x)`, `∂δ/∂u = (dt² a_u, dt a_u)`;
    /// - `F_x = [J_q^x [I 0] + J_q^δ ∂δ_q/∂x; [0 I] + dt a_x]`, `F_u = [J_q^δ dt² a_u; dt a_u]`,
    ///   with `J_q^x = ∂(q ⊕ δ_q)/∂q`, `J_q^δ = ∂(q ⊕ δ_q)/∂δ_q`.
    fn euler_jacobians(&self, d: &mut ActionData, x: &DVector<f64>, dt: f64) -> Result<()> {
        let nv = self.state.nv();
        self.state.jintegrate_q(&mut d.sc, x, &d.dx, Arg::First)?;
        d.jq_x.copy_from(&d.sc.jq);
        self.state.jintegrate_q(&mut d.sc, x, &d.dx, Arg::Second)?;
        d.jq_dx.copy_from(&d.sc.jq);
        // Bottom rows: [0 I] + dt a_x; dt a_u.
        {
            let mut bottom = d.fx.view_mut((nv, 0), (nv, 2 * nv));
            bottom.copy_from(&d.da_dx);
            bottom *= dt;
            for j in 0..nv {
                bottom[(j, nv + j)] += 1.0;
            }
        }
        {
            let mut bu = d.fu.view_mut((nv, 0), (nv, d.da_du.ncols()));
            bu.copy_from(&d.da_du);
            bu *= dt;
        }
        // Top rows: ∂δ_q/∂x = dt × (bottom rows) (= dt² a_x + dt [0 I]).
        let (top, bottom) = d.fx.rows_range_pair_mut(0..nv, nv..2 * nv);
        let mut top = top;
        gemm_nn(&mut top, dt, &d.jq_dx, &bottom, 0.0);
        let mut tl = top.view_mut((0, 0), (nv, nv));
        tl += &d.jq_x;
        let (tu, bu) = d.fu.rows_range_pair_mut(0..nv, nv..2 * nv);
        let mut tu = tu;
        gemm_nn(&mut tu, dt, &d.jq_dx, &bu, 0.0);
        Ok(())
    }

    fn eval_costs(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: &DVector<f64>,
        with_dynamics: bool,
        diff: bool,
        scale: f64,
    ) -> Result<()> {
        let with_u = with_dynamics && matches!(self.kind, ActionKind::Euler { .. });
        let forces = with_dynamics.then_some((&d.lambda, &d.dlambda_dx, &d.dlambda_du));
        let mut view = NodeView {
            model: self.state.model(),
            state: &self.state,
            data: &mut d.data,
            sc: &mut d.sc,
            x,
            q: &d.q,
            v: &d.v,
            u,
            forces,
        };
        // Impulse nodes have no control but evaluate every cost at (x, impulses).
        let eval_all = with_u || with_dynamics;
        let c = self.costs.calc(&mut d.costs, &mut view, eval_all)?;
        d.cost = scale * c;
        if diff {
            d.lx.as_mut_slice().fill(0.0);
            d.lu.as_mut_slice().fill(0.0);
            d.lxx.as_mut_slice().fill(0.0);
            d.lxu.as_mut_slice().fill(0.0);
            d.luu.as_mut_slice().fill(0.0);
            let mut derivs = CostDerivs {
                lx: &mut d.lx,
                lu: &mut d.lu,
                lxx: &mut d.lxx,
                lxu: &mut d.lxu,
                luu: &mut d.luu,
            };
            self.costs.calc_diff(&mut d.costs, &mut view, &mut derivs, eval_all)?;
            if scale != 1.0 {
                d.lx.as_mut_slice().iter_mut().for_each(|x| *x *= scale);
                d.lu.as_mut_slice().iter_mut().for_each(|x| *x *= scale);
                d.lxx.as_mut_slice().iter_mut().for_each(|x| *x *= scale);
                d.lxu.as_mut_slice().iter_mut().for_each(|x| *x *= scale);
                d.luu.as_mut_slice().iter_mut().for_each(|x| *x *= scale);
            }
        }
        Ok(())
    }
}
