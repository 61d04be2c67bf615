//! Kinematic trees: joints, the Model/builder, URDF and MJCF loading and built-in robots.

pub mod builtin;
mod contact;
pub mod joint;
pub mod lie;
pub mod mjcf;
pub(crate) mod reduction;
mod tendon;
pub mod tree;
pub mod urdf;

pub use contact::{Contact, ContactReference, ContactType};
pub(crate) use contact::{contact_label, redundancy};
pub use joint::JointType;
pub use lie::{Arg, exp6, jlog6, log6};
pub use mjcf::{MjcfOptions, load_mjcf_file, load_mjcf_str};
pub use reduction::{JointCoupling, LinearCoupling};
pub use tendon::{SpatialWrap, Tendon, TendonPath};
pub(crate) use tree::JointKin;
pub use tree::{Frame, Model, ModelBuilder, check_vec};
pub use urdf::{MAX_URDF_DOFS, ROOT_JOINT_NAME, UrdfOptions, load_urdf_file, load_urdf_str};
