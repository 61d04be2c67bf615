//! The automatic-differentiation **oracle**: deliberately simple, scalar-generic reference
//! implementations of the kinematics and dynamics of a [`Model`](crate::model::Model).
//!
//! Everything here is written once, generically over a scalar `T:` [`AdScalar`] (any
//! [`num_dual::DualNum`] with `f64` as its primitive: `f64`, [`num_dual::Dual64`],
//! [`num_dual::DualVec64`], [`num_dual::DualDVec64`], [`num_dual::HyperDual64`],
//! [`num_dual::HyperDualVec64`], ...). Running the same code with dual numbers yields exact
//! (to rounding) first and second derivatives, which the optimised analytical algorithms of
//! [`crate`] are tested against.
//!
//! Independence: this module does **not** use the optimised algorithms nor the `f64` methods of
//! the spatial types. It only reads the model description (joint types, parents, placements,
//! inertias, index tables, gravity, frames) and re-derives everything with its own tiny spatial
//! algebra ([`spatial`]), textbook recursions and a dense Gaussian elimination:
//!
//! * [`kinematics`]: joint transforms `X_J(q)`, the configuration integrator `q ⊕ δ`
//!   ([`integrate`], with series expansions around zero so that dual numbers at `δ = 0` get exact
//!   first *and* second derivatives), forward kinematics, frame placements and point positions;
//! * [`dynamics`]: the recursive Newton–Euler algorithm ([`rnea`]), the mass matrix by unit
//!   accelerations ([`mass_matrix`]), the nonlinear effects ([`nle`]) and forward dynamics by a
//!   dense solve ([`aba`]);
//! * [`contact`]: point-contact Jacobians and drifts, constrained inverse dynamics, KKT and
//!   impact dynamics, and their first/second-order `f64` oracles;
//! * [`reduced`]: the mimic expansion of a model in reduced coordinates (mimic joints), through
//!   which every function here takes such a model too: the reference algorithms run on the full
//!   tree at `expand(q)`, `G v`, and return the reduced quantities;
//! * [`derivatives`]: `f64`-valued convenience oracles, first order with [`num_dual::Dual64`]
//!   and second order with [`num_dual::HyperDual64`].
//!
//! Conventions (those of the crate): spatial vectors are `[angular; linear]`; quantities are
//! propagated in body (joint child) frames; derivatives with respect to `q` are **tangent**
//! derivatives, i.e. with respect to `δ` in `q ⊕ δ` at `δ = 0`, with `δ` a velocity-sized vector
//! (body-frame perturbation for spherical, free-flyer and planar joints).
//!
//! Speed is not a goal: the mass matrix costs `nv` RNEA passes, forward dynamics an `O(nv³)`
//! elimination, and a second-order tensor `nv²` such evaluations.

pub mod contact;
pub mod derivatives;
pub mod dynamics;
pub mod kinematics;
pub mod reduced;
pub mod spatial;

pub use contact::{
    ImpactFo, ImpactSo, KktFo, KktSo, constrained_rnea, contact_drift, contact_jacobian, impact,
    impact_fo, impact_so, kkt, kkt_fo, kkt_so,
};
pub use derivatives::{
    contracted_aba_hessians, contracted_rnea_hessians, d_aba_dq, d_aba_dtau, d_aba_dv,
    d_point_position_dq, d_rnea_dq, d_rnea_dv, d2_aba_dq2, d2_aba_dqdv, d2_aba_dtaudq, d2_aba_dv2,
    d2_rnea_dq2, d2_rnea_dqdv, d2_rnea_dv2, dM_dq,
};
pub use dynamics::{aba, mass_matrix, nle, rnea, rnea_with_gravity, solve};
pub use kinematics::{
    forward_kinematics, frame_placement, integrate, joint_transform, point_position,
};

use num_dual::DualNum;

/// The scalars the oracle runs with: any dual number (or `f64` itself) whose primitive is
/// `f64`. Blanket-implemented; only `Clone` is required, so dynamically sized duals such as
/// [`num_dual::DualDVec64`] work too.
pub trait AdScalar: DualNum<Primitive = f64> {}

impl<T: DualNum<Primitive = f64>> AdScalar for T {}

/// Lifts `f64` values into the scalar type `T` (derivative parts zero).
pub fn lift<T: AdScalar>(x: &[f64]) -> Vec<T> {
    x.iter().map(|&v| T::from(v)).collect()
}

/// Real parts of a slice of scalars.
pub fn real<T: AdScalar>(x: &[T]) -> Vec<f64> {
    x.iter().map(|v| v.re()).collect()
}
