//! Derivatives of the dynamics, one file per family of the notes.
//!
//! * [`id_fo`]: IDSVA, first-order ID derivatives;
//! * [`id_so`]: IDSVA-SO, second-order ID derivatives and `∂M/∂q`;
//! * [`zero`]: IDFOZA / IDSOZA zero-velocity shortcuts;
//! * [`fd`]: first- and second-order forward-dynamics derivatives;
//! * [`contracted`]: the second-order derivatives contracted with a weight vector (DDP).

pub mod contact;
pub mod contact_set;
pub mod contracted;
pub mod external;
pub mod fd;
pub mod id_fo;
pub mod id_so;
pub mod impact;
pub mod kkt;
pub mod zero;

pub use contact::MAX_CONTACTS;
pub use contact_set::{
    ContactData, constrained_id_derivatives, constrained_id_so_derivatives, impact_derivatives,
    impact_dynamics, impact_so_contracted, impact_so_derivatives, kkt_derivatives, kkt_dynamics,
    kkt_so_contracted, kkt_so_derivatives,
};
pub use contracted::{ContractedData, fd_so_contracted, id_so_contracted};
pub use fd::{FdSoData, fd_derivatives, fd_so_derivatives};
pub use id_fo::id_derivatives;
pub use id_so::{SoData, id_so_derivatives};
pub use impact::{ImpactContracted, ImpactData, ImpactSo};
pub use kkt::{KktContracted, KktData, KktSo};
pub use zero::{idfoza, idsoza};
pub(crate) mod contact_kin;
pub(crate) mod contact_loop;
