//! First- and second-order derivatives of inverse and forward dynamics, contracted and dense, plain
//! and in reduced coordinates (mimic joints).

mod contracted;
mod id_fd;
mod mimic;
mod mimic_contracted;
