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

/// A library message (an error or a loader warning) in the command line's terms: the Rust API
/// it names for library users (`Type::method`) is rewritten. The regularised contact solve
/// (`ContactData::set_damping`) is the state file's `"damping"` key; a `Model` accessor
/// (`Model::tendons`) is named as what the model records; any other `Type::name` is `name`.
pub fn cli_message(s: &str) -> String {
    if !s.contains("::") {
        return s.to_owned();
    }
    let ident = |c: char| c.is_ascii_alphanumeric() || c == '_';
    let mut out = String::with_capacity(s.len());
    let mut rest = s;
    while let Some(p) = rest.find("::") {
        let start = rest[..p].rfind(|c: char| !ident(c)).map_or(0, |i| i + 1);
        let tail = &rest[p + 2..];
        let end = tail.find(|c: char| !ident(c)).unwrap_or(tail.len());
        out.push_str(&rest[..start]);
        match (&rest[start..p], &tail[..end]) {
            (_, "set_damping") => out.push_str("the state file's \"damping\" key"),
            ("Model", name) => {
                out.push_str("in the model's ");
                out.push_str(name);
            }
            (_, other) => out.push_str(other),
        }
        rest = &tail[end..];
    }
    out.push_str(rest);
    out
}

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
