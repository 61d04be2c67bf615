//! The integration tests of `sodyn`, one crate (one link step) with a folder per family:
//! `cargo test --profile ci --test all`, or one family or file by name filter
//! (`cargo test --profile ci --test all -- derivatives::mimic`). Test data are read from
//! `tests/data`, `tests/fixtures` and `../shared/models` through `CARGO_MANIFEST_DIR`.

mod api;
#[cfg(feature = "cli")]
mod cli;
mod contacts;
mod derivatives;
mod dynamics;
mod kinematics;
mod loaders;
mod oracle;
mod pinocchio;
mod util;
