//! `sodyn._sodyn`: the Python binding of sodyn (PyO3 + numpy), wrapped by the pure-Python
//! package `sodyn` (`python/python/sodyn/__init__.py`).
//!
//! Every call copies its inputs into buffers kept in the `Data` object (no allocation after the
//! first call), releases the GIL for the computation and returns fresh numpy arrays (never
//! views into `Data`). Matrices and tensors are returned in Fortran order, which is sodyn's
//! storage order: `M[i, j]`, `T[i, j, k]` as in `docs/conventions.md`.
//!
//! Errors: every `sodyn::Error` becomes `sodyn.SodynError` (a `ValueError`) with the same
//! message; an argument that does not convert to a float64 array of the expected shape is a
//! `ValueError` naming the argument and the shape. No input reaches a panic: the core returns
//! errors for every invalid input, and this crate indexes nothing that it has not checked.
//!
//! One module per family, each with a `register` function that adds its classes and
//! functions to the extension module.

use pyo3::prelude::*;

mod batch;
mod contacts;
mod convert;
mod data;
mod derivatives;
mod dynamics;
mod jax_ffi;
mod kinematics;
mod model;
mod ocp;
mod pinocchio;

/// The compiled module `sodyn._sodyn`.
#[pymodule]
fn _sodyn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    convert::register(m)?;
    model::register(m)?;
    data::register(m)?;
    dynamics::register(m)?;
    derivatives::register(m)?;
    contacts::register(m)?;
    kinematics::register(m)?;
    batch::register(m)?;
    ocp::register(m)?;
    jax_ffi::register(m)?;
    Ok(())
}
