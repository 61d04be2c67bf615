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
//! 2. [`ActionKind::RungeKutta`]: the same differential dynamics integrated by an explicit
//!    Runge-Kutta scheme ([`RkType`]: Crocoddyl's `IntegratedActionModelRK`), the derivatives by
//!    the chain rule through the stages and `⊕` (exact first order; Gauss-Newton cost Hessian);
//!    no second order ([`ActionModel::second_order`] refuses such a knot);
//! 3. [`ActionKind::Impulse`]: impulse dynamics at a contact switch (Crocoddyl's
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
use crate::linalg::{gemm_nn, gemm_tn};
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
    /// Differential dynamics integrated by an explicit Runge-Kutta scheme over `dt`
    /// (Crocoddyl's `IntegratedActionModelRK`, `PolyZero` controls; see [`RkType`]).
    RungeKutta {
        /// The scheme.
        rk: RkType,
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

/// An explicit Runge-Kutta scheme of Crocoddyl's `IntegratedActionModelRK` (`RKType`), with
/// stages `y_0 = x`, `y_i = x ⊕ dt c_i k_{i−1}` (every stage from `x`), `k_i = (v(y_i), a(y_i, u))`
/// the tangent of the stage (its velocity and acceleration), `x′ = x ⊕ dt Σ b_i k_i` and the
/// cost `dt Σ b_i ℓ_c(y_i, u)`:
///
/// | scheme | `c` | `b` |
/// |---|---|---|
/// | [`RkType::Two`] | `0, ½` | `0, 1` |
/// | [`RkType::Three`] | `0, ⅓, ⅔` | `¼, 0, ¾` |
/// | [`RkType::Four`] | `0, ½, ½, 1` | `⅙, ⅓, ⅓, ⅙` |
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RkType {
    /// Two stages (the midpoint rule).
    Two,
    /// Three stages (Heun's third order).
    Three,
    /// Four stages (the classical RK4).
    Four,
}

impl RkType {
    /// The nodes `c` and weights `b` (the table of [`RkType`]).
    pub fn tableau(self) -> (&'static [f64], &'static [f64]) {
        match self {
            RkType::Two => (&[0.0, 0.5], &[0.0, 1.0]),
            RkType::Three => (&[0.0, 1.0 / 3.0, 2.0 / 3.0], &[0.25, 0.0, 0.75]),
            RkType::Four => (&[0.0, 0.5, 0.5, 1.0], &[1.0 / 6.0, 1.0 / 3.0, 1.0 / 3.0, 1.0 / 6.0]),
        }
    }
    /// `"RK2"`, `"RK3"` or `"RK4"`.
    pub fn name(self) -> &'static str {
        match self {
            RkType::Two => "RK2",
            RkType::Three => "RK3",
            RkType::Four => "RK4",
        }
    }
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
    /// Runge-Kutta buffers (Runge-Kutta knots only).
    rk: Option<Box<RkWork>>,
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

/// Buffers of a Runge-Kutta knot: the stage state `y`, its tangent `k`, `δ = dt Σ b_i k_i`, the
/// stage step `dt c_i k`, and the derivatives `∂y/∂(x, u)`, `∂k/∂(x, u)`, `∂δ/∂(x, u)`; the
/// cost terms' accumulators.
#[derive(Clone, Debug)]
struct RkWork {
    y: DVector<f64>,
    k: DVector<f64>,
    delta: DVector<f64>,
    step: DVector<f64>,
    dy_dx: DMatrix<f64>,
    dy_du: DMatrix<f64>,
    dk_dx: DMatrix<f64>,
    dk_du: DMatrix<f64>,
    ddelta_dx: DMatrix<f64>,
    ddelta_du: DMatrix<f64>,
    lxx_dy: DMatrix<f64>,
    lxx_du: DMatrix<f64>,
    lx: DVector<f64>,
    lu: DVector<f64>,
    lxx: DMatrix<f64>,
    lxu: DMatrix<f64>,
    luu: DMatrix<f64>,
}

impl RkWork {
    fn new(nx: usize, ndx: usize, nu: usize) -> RkWork {
        RkWork {
            y: DVector::zeros(nx),
            k: DVector::zeros(ndx),
            delta: DVector::zeros(ndx),
            step: DVector::zeros(ndx),
            dy_dx: DMatrix::zeros(ndx, ndx),
            dy_du: DMatrix::zeros(ndx, nu),
            dk_dx: DMatrix::zeros(ndx, ndx),
            dk_du: DMatrix::zeros(ndx, nu),
            ddelta_dx: DMatrix::zeros(ndx, ndx),
            ddelta_du: DMatrix::zeros(ndx, nu),
            lxx_dy: DMatrix::zeros(ndx, ndx),
            lxx_du: DMatrix::zeros(ndx, nu),
            lx: DVector::zeros(ndx),
            lu: DVector::zeros(nu),
            lxx: DMatrix::zeros(ndx, ndx),
            lxu: DMatrix::zeros(ndx, nu),
            luu: DMatrix::zeros(nu, nu),
        }
    }
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
            ActionKind::Euler { .. } | ActionKind::RungeKutta { .. } => {
                self.actuation.nu(self.model())
            }
            ActionKind::Impulse { .. } => 0,
        }
    }
    /// Whether the knot's dynamics take a control (Euler and Runge-Kutta knots).
    fn controlled(&self) -> bool {
        !matches!(self.kind, ActionKind::Impulse { .. })
    }
    /// The contacts of the knot.
    pub fn contacts(&self) -> &[NamedContact] {
        match &self.kind {
            ActionKind::Euler { contacts, .. }
            | ActionKind::RungeKutta { contacts, .. }
            | ActionKind::Impulse { contacts, .. } => contacts,
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
                ActionKind::Euler { damping, .. } | ActionKind::RungeKutta { damping, .. } => {
                    *damping
                }
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
            rk: matches!(self.kind, ActionKind::RungeKutta { .. })
                .then(|| Box::new(RkWork::new(self.state.nx(), ndx, nu))),
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

    /// A knot without control: no dynamics (`x′ = x`, `F_x = I`), the costs of `x` alone
    /// (Crocoddyl's terminal `calc(x)`), for every integrator.
    fn eval_terminal(&self, d: &mut ActionData, x: &DVector<f64>, diff: bool) -> Result<()> {
        d.xnext.copy_from(x);
        d.a.fill(0.0);
        if diff {
            d.fx.fill(0.0);
            d.fx.fill_diagonal(1.0);
        }
        self.eval_costs(d, x, &DVector::zeros(0), false, diff, 1.0)
    }

    fn eval(
        &self,
        d: &mut ActionData,
        x: &DVector<f64>,
        u: Option<&DVector<f64>>,
        diff: bool,
    ) -> Result<()> {
        // A borrow (no Arc clone: the knots share one Model, whose reference count would
        // bounce between the threads evaluating them).
        let m: &Model = self.state.model();
        let (nq, nv) = (m.nq(), m.nv());
        d.q.copy_from(&x.rows(0, nq));
        d.v.copy_from(&x.rows(nq, nv));
        let zero_u = DVector::zeros(0);
        let with_dynamics;
        let mut cost_scale = 1.0;
        match &self.kind {
            ActionKind::Euler { dt, .. } => {
                let Some(u) = u else {
                    return self.eval_terminal(d, x, diff);
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
            ActionKind::RungeKutta { rk, dt, .. } => {
                let Some(u) = u else {
                    return self.eval_terminal(d, x, diff);
                };
                let mut w = d.rk.take().ok_or_else(|| {
                    OcpError::new("Runge-Kutta knot: the data was made for another knot")
                })?;
                let r = self.eval_rk(m, d, &mut w, *rk, *dt, x, u, diff);
                d.rk = Some(w);
                r
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
        // A borrow (no Arc clone: the knots share one Model, whose reference count would
        // bounce between the threads evaluating them).
        let m: &Model = self.state.model();
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
        if let (ActionKind::Euler { .. }, Some(_)) = (&self.kind, u)
            && let Some(c) = self
                .contacts()
                .iter()
                .find(|c| c.active && c.contact.world_ref.is_some() && c.contact.kp != 0.0)
        {
            return Err(OcpError::new(format!(
                "contact '{}': the exact second order (second_order = True / \"auto\") of a \
                 Baumgarte position gain kp against a world reference (xref) is not \
                 implemented; solve with second_order = False",
                c.name
            )));
        }
        d.hzz.fill(0.0);
        d.so.w_lambda.fill(0.0);
        let zero_u = DVector::zeros(0);
        let (dt, dynamics) = match (&self.kind, u) {
            (ActionKind::Euler { dt, .. }, Some(_)) => (*dt, true),
            (ActionKind::Euler { .. } | ActionKind::RungeKutta { .. }, None) => (1.0, false),
            (ActionKind::RungeKutta { rk, .. }, Some(_)) => {
                return Err(OcpError::new(format!(
                    "{} integrator: the exact second order (second_order = True / \"auto\") of \
                     a Runge-Kutta knot is not implemented; solve with second_order = False",
                    rk.name()
                )));
            }
            (ActionKind::Impulse { .. }, _) => (1.0, true),
        };
        // 3. The costs' curvature (and their weight on the forces).
        {
            let with_u = dynamics && self.controlled();
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
            // Refused above (a Runge-Kutta knot with a control).
            ActionKind::RungeKutta { .. } => {}
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

    /// A Runge-Kutta knot ([`RkType`]) at `(x, u)`, with the exact first-order chain rule
    /// through `⊕` and the stages:
    /// - `∂y_0/∂x = I`; `∂y_i/∂x = J₁(x, s_i) + J₂(x, s_i) dt c_i ∂k_{i−1}/∂x` with
    ///   `s_i = dt c_i k_{i−1}`, `J₁ = ∂(x ⊕ s)/∂x`, `J₂ = ∂(x ⊕ s)/∂s` (and `∂y_i/∂u =
    ///   J₂ dt c_i ∂k_{i−1}/∂u`);
    /// - `∂k_i/∂x = [∂v(y_i)/∂x; a_y ∂y_i/∂x]`, `∂k_i/∂u = [∂v(y_i)/∂u; a_y ∂y_i/∂u + a_u]`;
    /// - `F_x = J₁(x, δ) + J₂(x, δ) ∂δ/∂x`, `F_u = J₂(x, δ) ∂δ/∂u`, `δ = dt Σ b_i k_i`;
    /// - the cost derivatives, with `w_i = dt b_i` and `Y_x = ∂y_i/∂x`, `Y_u = ∂y_i/∂u`:
    ///   `ℓ_x = Σ w_i Y_xᵀ ℓ_y`, `ℓ_u = Σ w_i (Y_uᵀ ℓ_y + ℓ_u)` and the Gauss-Newton Hessian
    ///   `ℓ_xx = Σ w_i Y_xᵀ ℓ_yy Y_x`, `ℓ_xu = Σ w_i Y_xᵀ (ℓ_yy Y_u + ℓ_yu)`,
    ///   `ℓ_uu = Σ w_i (Y_uᵀ ℓ_yy Y_u + Y_uᵀ ℓ_yu + ℓ_uy Y_u + ℓ_uu)` (the stages' curvature
    ///   `ℓ_yᵀ ∂²y_i` left out, as Crocoddyl does).
    ///
    /// Afterwards `d.a`, `d.lambda` (and their derivatives) are those of the last stage.
    #[allow(clippy::too_many_arguments)]
    fn eval_rk(
        &self,
        m: &Model,
        d: &mut ActionData,
        w: &mut RkWork,
        rk: RkType,
        dt: f64,
        x: &DVector<f64>,
        u: &DVector<f64>,
        diff: bool,
    ) -> Result<()> {
        let (nq, nv) = (m.nq(), m.nv());
        let (c, b) = rk.tableau();
        let off = self.actuation.offset();
        d.tau.fill(0.0);
        d.tau.rows_mut(off, u.len()).copy_from(u);
        w.delta.fill(0.0);
        let mut cost = 0.0;
        if diff {
            w.ddelta_dx.fill(0.0);
            w.ddelta_du.fill(0.0);
            w.lx.fill(0.0);
            w.lu.fill(0.0);
            w.lxx.fill(0.0);
            w.lxu.fill(0.0);
            w.luu.fill(0.0);
        }
        for i in 0..c.len() {
            if i == 0 {
                w.y.copy_from(x);
                if diff {
                    w.dy_dx.fill(0.0);
                    w.dy_dx.fill_diagonal(1.0);
                    w.dy_du.fill(0.0);
                }
            } else {
                let h = dt * c[i];
                w.step.copy_from(&w.k);
                w.step *= h;
                self.state.integrate(x, &w.step, &mut w.y);
                if diff {
                    self.state.jintegrate_q(&mut d.sc, x, &w.step, Arg::First)?;
                    d.jq_x.copy_from(&d.sc.jq);
                    self.state.jintegrate_q(&mut d.sc, x, &w.step, Arg::Second)?;
                    // q rows: J_q^s h ∂k_q/∂(x, u) (+ J_q^x on the q columns); v rows: h ∂k_v + [0 I].
                    {
                        let mut top = w.dy_dx.rows_mut(0, nv);
                        gemm_nn(&mut top, h, &d.sc.jq, &w.dk_dx.rows(0, nv), 0.0);
                        let mut tl = top.view_mut((0, 0), (nv, nv));
                        tl += &d.jq_x;
                    }
                    {
                        let mut top = w.dy_du.rows_mut(0, nv);
                        gemm_nn(&mut top, h, &d.sc.jq, &w.dk_du.rows(0, nv), 0.0);
                    }
                    for r in nv..2 * nv {
                        for col in 0..2 * nv {
                            w.dy_dx[(r, col)] = h * w.dk_dx[(r, col)];
                        }
                        w.dy_dx[(r, r)] += 1.0;
                        for col in 0..w.dy_du.ncols() {
                            w.dy_du[(r, col)] = h * w.dk_du[(r, col)];
                        }
                    }
                }
            }
            d.q.copy_from(&w.y.rows(0, nq));
            d.v.copy_from(&w.y.rows(nq, nv));
            self.forward_dynamics(m, d, diff).map_err(|e| {
                e.context(&format!("{} stage {} (of {})", rk.name(), i + 1, c.len()))
            })?;
            w.k.rows_mut(0, nv).copy_from(&d.v);
            w.k.rows_mut(nv, nv).copy_from(&d.a);
            w.delta.axpy(dt * b[i], &w.k, 1.0);
            if diff {
                // ∂k/∂(x, u) = [∂v_y; a_y ∂y + (0, a_u)].
                for r in 0..nv {
                    for col in 0..2 * nv {
                        w.dk_dx[(r, col)] = w.dy_dx[(nv + r, col)];
                    }
                    for col in 0..w.dy_du.ncols() {
                        w.dk_du[(r, col)] = w.dy_du[(nv + r, col)];
                    }
                }
                {
                    let mut bot = w.dk_dx.rows_mut(nv, nv);
                    gemm_nn(&mut bot, 1.0, &d.da_dx, &w.dy_dx, 0.0);
                }
                {
                    let mut bot = w.dk_du.rows_mut(nv, nv);
                    bot.copy_from(&d.da_du);
                    gemm_nn(&mut bot, 1.0, &d.da_dx, &w.dy_du, 1.0);
                }
                w.ddelta_dx.zip_apply(&w.dk_dx, |a, k| *a += dt * b[i] * k);
                w.ddelta_du.zip_apply(&w.dk_du, |a, k| *a += dt * b[i] * k);
            }
            if b[i] == 0.0 {
                continue;
            }
            let wi = dt * b[i];
            self.eval_costs(d, &w.y, u, true, diff, 1.0)?;
            cost += wi * d.cost;
            if diff {
                w.lx.gemv_tr(wi, &w.dy_dx, &d.lx, 1.0);
                w.lu.gemv_tr(wi, &w.dy_du, &d.lx, 1.0);
                w.lu.axpy(wi, &d.lu, 1.0);
                gemm_nn(&mut w.lxx_dy, 1.0, &d.lxx, &w.dy_dx, 0.0);
                gemm_nn(&mut w.lxx_du, 1.0, &d.lxx, &w.dy_du, 0.0);
                w.lxx_du += &d.lxu;
                gemm_tn(&mut w.lxx, wi, &w.dy_dx, &w.lxx_dy, 1.0);
                gemm_tn(&mut w.lxu, wi, &w.dy_dx, &w.lxx_du, 1.0);
                // ℓ_uu: Y_uᵀ (ℓ_yy Y_u + ℓ_yu) + ℓ_uyᵀ... = Y_uᵀ lxx_du + ℓ_yuᵀ Y_u + ℓ_uu.
                gemm_tn(&mut w.luu, wi, &w.dy_du, &w.lxx_du, 1.0);
                gemm_tn(&mut w.luu, wi, &d.lxu, &w.dy_du, 1.0);
                w.luu.zip_apply(&d.luu, |a, l| *a += wi * l);
            }
        }
        self.state.integrate(x, &w.delta, &mut d.xnext);
        d.cost = cost;
        if diff {
            d.lx.copy_from(&w.lx);
            d.lu.copy_from(&w.lu);
            d.lxx.copy_from(&w.lxx);
            d.lxu.copy_from(&w.lxu);
            d.luu.copy_from(&w.luu);
            self.state.jintegrate_q(&mut d.sc, x, &w.delta, Arg::First)?;
            d.jq_x.copy_from(&d.sc.jq);
            self.state.jintegrate_q(&mut d.sc, x, &w.delta, Arg::Second)?;
            d.jq_dx.copy_from(&d.sc.jq);
            {
                let mut top = d.fx.rows_mut(0, nv);
                gemm_nn(&mut top, 1.0, &d.jq_dx, &w.ddelta_dx.rows(0, nv), 0.0);
                let mut tl = top.view_mut((0, 0), (nv, nv));
                tl += &d.jq_x;
            }
            {
                let mut top = d.fu.rows_mut(0, nv);
                gemm_nn(&mut top, 1.0, &d.jq_dx, &w.ddelta_du.rows(0, nv), 0.0);
            }
            d.fx.rows_mut(nv, nv).copy_from(&w.ddelta_dx.rows(nv, nv));
            for j in 0..nv {
                d.fx[(nv + j, nv + j)] += 1.0;
            }
            d.fu.rows_mut(nv, nv).copy_from(&w.ddelta_du.rows(nv, nv));
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
        let with_u = with_dynamics && self.controlled();
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
