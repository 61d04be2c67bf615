//! Algorithms: kinematics, RNEA, CRBA, ABA, the tree-sparse `LᵀDL` factorisation, Jacobians.

pub(crate) mod aba;
pub(crate) mod centroidal;
pub(crate) mod com;
pub(crate) mod crba;
pub(crate) mod data;
pub(crate) mod frames;
pub(crate) mod jacobian;
pub(crate) mod kinematics;
mod ltl;
pub(crate) mod rnea;

/// Re-export of [`crate::model::Contact`] (the contact description is a model-level type).
pub use crate::model::{Contact, ContactReference, ContactType};
pub use aba::aba;
pub use centroidal::{centroidal_dynamics_derivatives, centroidal_momentum};
pub use com::{
    center_of_mass, center_of_mass_jacobian, center_of_mass_motion,
    center_of_mass_velocity_derivatives,
};
pub use crba::crba;
pub use data::Centroidal;
pub use data::Data;
pub use frames::{
    ReferenceFrame, frame_acceleration, frame_acceleration_derivatives,
    frame_classical_acceleration, frame_jacobian, frame_jacobian_derivative, frame_placement,
    frame_placement_hessian, frame_velocity, frame_velocity_derivatives,
};
pub use jacobian::{point_drift, point_jacobian, point_position};
pub use kinematics::forward_kinematics;
pub use ltl::{factorize_ltl, solve_ltl, solve_ltl_matrix};
pub use rnea::{nonlinear_effects, rnea};

/// Crate-internal unchecked building blocks shared with the derivative algorithms.
pub(crate) mod internal {
    pub(crate) use super::aba::aba_unchecked;
    pub(crate) use super::crba::crba_unchecked;
    pub(crate) use super::kinematics::{placements, root_free_flyer};
    pub(crate) use super::ltl::{PIVOT_RTOL, ltl_in_place, ltl_solve_fd, ltl_solve_rows_desc};
    pub(crate) use super::rnea::{check_fext, rnea_unchecked};
}
