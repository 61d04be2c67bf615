//! # sodyn-ocp
//!
//! Optimal control on [`sodyn`]: Crocoddyl's shooting problems (multibody state on the
//! configuration manifold, full or floating-base actuation, free and contact forward dynamics
//! integrated by symplectic Euler or explicit Runge-Kutta (RK2/3/4), impulse dynamics at contact switches, weighted sums of
//! activated residuals) and the DDP, FDDP and box-FDDP solvers with Crocoddyl's semantics.
//! Conventions are sodyn's (`docs/conventions.md`: spatial vectors `[angular; linear]`,
//! free-flyer `v = [ω; v]` in the body frame); `docs/ocp.md` maps Crocoddyl's layout.
//!
//! Layout: [`state`] (`⊕`, `⊖` and their Jacobians), [`activation`], [`residual`], [`cost`],
//! [`action`] (the knots), [`problem`] (a horizon of knots, evaluated in parallel), [`solver`],
//! [`spec`] (problems described as data, for the Python binding and files).
#![deny(missing_docs)]

pub mod action;
pub mod activation;
pub mod cost;
mod curvature;
pub mod error;
mod linalg;
pub mod problem;
mod quasi_static;
pub mod residual;
pub mod solver;
pub mod spec;
pub mod state;

pub use action::{ActionData, ActionKind, ActionModel, Actuation, NamedContact, RkType};
pub use activation::Activation;
pub use cost::{CostItem, CostModelSum};
pub use error::{OcpError, Result};
pub use problem::ShootingProblem;
pub use residual::Residual;
pub use solver::{HessianStats, IterationLog, SecondOrder, Solver, SolverKind, Termination};
pub use state::StateMultibody;
