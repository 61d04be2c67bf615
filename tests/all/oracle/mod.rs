//! The automatic-differentiation oracles (`sodyn::reference`) against independent facts.

mod reference;
mod reference_contact;
