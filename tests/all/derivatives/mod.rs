//! First- and second-order derivatives of inverse and forward dynamics, contracted and dense, plain
//! and in reduced coordinates (the mimic models of `util::test_models`).

mod contracted;
mod id_fd;
