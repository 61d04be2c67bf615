//! The `sodyn` binary (feature `cli`).

mod commands;
