//! Dynamics: RNEA, CRBA, ABA, the LᵀDL factorisation, armature, singular mass matrices and the
//! forward-only functions of reduced models.

mod armature;
mod basics;
mod mimic_forward;
mod singular;
