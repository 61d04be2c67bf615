//! # sodyn
//!
//! Rigid-body dynamics and its exact first- and second-order derivatives, following the notes
//! "Details of Partial Derivatives of Rigid-Body Inverse Dynamics" (Singh, Russell, Wensing).
//!
//! Layout: [`spatial`] (spatial vector algebra), [`model`] (joints, kinematic trees, URDF and
//! MJCF loading, built-in robots), [`algo`] (kinematics, RNEA, CRBA, ABA, LTLᵀ, Jacobians), [`reference`](mod@reference)
//! (scalar-generic algorithms used as the automatic-differentiation oracle).
//! Conventions are in `docs/conventions.md`.
#![deny(missing_docs)]

pub mod algo;
pub mod batch;
/// Thin wrappers of the crate-private dense kernels for the `linalg_vs_faer` example (feature
/// `bench-internals`); not part of the API.
#[cfg(feature = "bench-internals")]
#[doc(hidden)]
pub mod bench_internals;
pub mod deriv;
pub mod error;
mod linalg;
pub mod model;
pub mod reference;
pub mod rng;
pub mod simd;
pub mod spatial;
pub mod tensor;
mod trig;

pub use error::{Error, Result};
/// The linear-algebra crate of the public API (vectors and matrices are `nalgebra` types).
pub use nalgebra;

/// The README's Rust code blocks, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
