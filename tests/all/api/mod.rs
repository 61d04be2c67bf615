//! The API around the algorithms: batches, workspace reuse and misuse, no allocation, reduced
//! models, SIMD levels, fuzz regressions.

mod batch;
mod data_reuse;
mod fuzz_regressions;
mod house;
mod no_alloc;
mod reduced_model;
mod simd_levels;
