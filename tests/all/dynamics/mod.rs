//! Dynamics: RNEA, CRBA, ABA, the nonlinear effects, the LᵀDL factorisation, the armature's
//! relations and singular mass matrices, on every test model (reduced ones included).

mod basics;
mod singular;
