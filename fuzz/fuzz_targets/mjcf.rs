//! Fuzz target `mjcf`: the MJCF loader on arbitrary bytes (with and without the floating-base
//! option), then rnea, nonlinear_effects, crba, aba, id_derivatives and fd_derivatives on what
//! loads, at the neutral state and a bounded random state. The checks are in `checks.rs`.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
mod checks;

fuzz_target!(|bytes: &[u8]| {
    checks::mjcf(bytes);
});
