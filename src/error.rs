//! The crate's error type: every failure names what is wrong and where.

use std::fmt;

/// Errors returned by the public API.
#[derive(Clone, Debug, PartialEq)]
pub enum Error {
    /// A URDF (or other model description) could not be loaded.
    Model {
        /// File (or `<string>`).
        file: String,
        /// 1-based line of the offending element, if known.
        line: Option<u32>,
        /// The element (e.g. `joint "knee"`).
        element: String,
        /// Why.
        reason: String,
    },
    /// A model-building call was invalid (builder API).
    Build(String),
    /// An input vector has the wrong length.
    Dimension {
        /// Which input (e.g. `q`).
        what: String,
        /// Expected length.
        expected: usize,
        /// Given length.
        got: usize,
    },
    /// An input has a NaN or infinite entry.
    NotFinite {
        /// Which input.
        what: String,
        /// Index of the first bad entry.
        index: usize,
    },
    /// A configuration is invalid (e.g. a quaternion that is not unit norm).
    InvalidConfiguration {
        /// Joint name.
        joint: String,
        /// Why.
        reason: String,
    },
    /// A matrix that must be factorised is singular or not positive definite.
    Singular {
        /// Which algorithm / matrix.
        what: String,
        /// Detail (pivot, joint...).
        detail: String,
    },
    /// An unknown name (frame, joint, model).
    Unknown {
        /// What kind of thing.
        kind: String,
        /// The name that was asked for.
        name: String,
    },
    /// An argument out of its domain (a negative restitution, a NaN damping, …).
    Argument {
        /// The argument.
        name: String,
        /// Why.
        reason: String,
    },
    /// A workspace (`Data`, `ContactData`, …) used with a model it was not made for.
    Workspace(String),
    /// The content of an input file outside the model (a state file, a JSON document) is
    /// invalid: a syntax error, an unknown key, a value of the wrong kind or length.
    Input {
        /// The file.
        file: String,
        /// 1-based line and column of the problem in the file, where known (JSON syntax and
        /// type errors).
        at: Option<(usize, usize)>,
        /// Why.
        reason: String,
    },
    /// An input/output failure: a file that cannot be read or written, a thread that cannot be
    /// started or pinned.
    Io(String),
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Model { file, line, element, reason } => match line {
                Some(l) => write!(f, "{file}:{l}: {element}: {reason}"),
                None => write!(f, "{file}: {element}: {reason}"),
            },
            Error::Build(s) => write!(f, "model build error: {s}"),
            Error::Dimension { what, expected, got } => {
                write!(f, "`{what}` has length {got}, expected {expected}")
            }
            Error::NotFinite { what, index } => {
                write!(f, "`{what}` has a non-finite entry at index {index}")
            }
            Error::InvalidConfiguration { joint, reason } => {
                write!(f, "invalid configuration of joint \"{joint}\": {reason}")
            }
            Error::Singular { what, detail } => write!(f, "{what} is singular: {detail}"),
            Error::Unknown { kind, name } => write!(f, "unknown {kind} \"{name}\""),
            Error::Argument { name, reason } => write!(f, "`{name}`: {reason}"),
            Error::Workspace(s) => write!(f, "workspace mismatch: {s}"),
            Error::Input { file, at, reason } => match at {
                Some((line, column)) => write!(f, "{file}:{line}:{column}: {reason}"),
                None => write!(f, "{file}: {reason}"),
            },
            Error::Io(s) => write!(f, "{s}"),
        }
    }
}

impl std::error::Error for Error {}

/// Result alias.
pub type Result<T> = std::result::Result<T, Error>;
