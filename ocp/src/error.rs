//! The error of the optimal-control layer: a message naming the node, the model part and the
//! argument.

use std::fmt;

/// An optimal-control error (bad problem description, bad warm start, a singular node).
#[derive(Clone, Debug, PartialEq)]
pub struct OcpError {
    /// What went wrong, naming the node and the part.
    pub message: String,
}

impl OcpError {
    /// An error with this message.
    pub fn new(message: impl Into<String>) -> Self {
        OcpError { message: message.into() }
    }
    /// The same error with `prefix: ` in front.
    pub fn context(self, prefix: &str) -> Self {
        OcpError { message: format!("{prefix}: {}", self.message) }
    }
}

impl fmt::Display for OcpError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for OcpError {}

impl From<sodyn::Error> for OcpError {
    fn from(e: sodyn::Error) -> Self {
        OcpError::new(e.to_string())
    }
}

/// Results of this crate.
pub type Result<T> = std::result::Result<T, OcpError>;
