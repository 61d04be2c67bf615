//! Standard output and standard error without panics (`println!` panics when the reader of a
//! pipe has gone, e.g. `sodyn bench | head -1`).
//!
//! * `outln!` and `out!` write to standard output. When it is
//!   closed (`BrokenPipe`), the process ends at once, quietly, with [`CLOSED_EXIT`] (0: the
//!   reader took what it wanted, as `head` does); any other write error is reported on standard
//!   error and ends the process with status 1.
//! * `errln!` writes to standard error and ignores its errors: a closed
//!   standard error leaves nowhere to report to, and the command goes on to its own status.

use std::io::{ErrorKind, Write};

/// Exit status when standard output is closed while a command writes to it.
pub const CLOSED_EXIT: i32 = 0;

/// Writes `args` to standard output (see the module documentation).
pub fn stdout(args: std::fmt::Arguments) {
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_fmt(args).and_then(|()| out.flush()) {
        if e.kind() == ErrorKind::BrokenPipe {
            std::process::exit(CLOSED_EXIT);
        }
        stderr(format_args!("sodyn: error: cannot write to standard output: {e}\n"));
        std::process::exit(1);
    }
}

/// Writes `args` to standard error, ignoring errors.
pub fn stderr(args: std::fmt::Arguments) {
    let _ = std::io::stderr().lock().write_fmt(args);
}

/// `print!` that ends the process quietly when standard output is closed.
macro_rules! out {
    ($($t:tt)*) => { $crate::out::stdout(format_args!($($t)*)) };
}

/// `println!` that ends the process quietly when standard output is closed.
macro_rules! outln {
    () => { $crate::out::stdout(format_args!("\n")) };
    ($($t:tt)*) => { $crate::out::stdout(format_args!("{}\n", format_args!($($t)*))) };
}

/// `eprintln!` that ignores a closed standard error.
macro_rules! errln {
    ($($t:tt)*) => { $crate::out::stderr(format_args!("{}\n", format_args!($($t)*))) };
}
