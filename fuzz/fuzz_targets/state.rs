//! Fuzz target `state`: the command line's state-file parser and `eval` (values, first- and
//! second-order derivatives, constrained inverse dynamics, KKT and impact derivatives with the
//! contacts of the file) on arbitrary bytes. The checks are in `checks.rs`.
#![no_main]

use libfuzzer_sys::fuzz_target;

#[allow(dead_code)]
mod checks;

fuzz_target!(|bytes: &[u8]| {
    checks::state(bytes);
});
