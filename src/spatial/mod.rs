//! Spatial vector algebra (Featherstone), shaped like the notes' section
//! "Spatial Vector Algebra Identities and Properties". Spatial vectors are `[angular; linear]`.

mod cross;
mod force;
mod inertia;
#[cfg(target_arch = "x86_64")]
pub(crate) mod lanes;
mod matrix;
mod motion;
mod transform;

pub use cross::{coriolis_b, coriolis_b_mul, crff, cross_f, cross_m};
#[allow(unused_imports)]
pub(crate) use cross::{coriolis_b_left, coriolis_b_write};
pub use force::Force;
pub use inertia::{Inertia, InertiaDefect};
pub use matrix::*;
pub use motion::{Motion, skew};
#[allow(unused_imports)]
pub(crate) use motion::{cross3, dot6, mat3_mul, mat3_tr_vec, mat3_vec};
pub use transform::Transform;
