//! Errors of phloem-core. Every variant names the offending argument so the Python layer
//! can raise a `ValueError` a user can act on.

use thiserror::Error;

/// Everything that can go wrong in phloem-core.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum Error {
    /// An argument has the wrong shape, size or value.
    #[error("{name}: {message}")]
    InvalidArgument {
        /// The parameter name as the user wrote it.
        name: &'static str,
        /// What was expected and what was given.
        message: String,
    },
    /// An internal failure (a bug, or the thread pool could not be built).
    #[error("internal error: {0}")]
    Internal(String),
    /// The run was stopped through its [`crate::cancel::Token`].
    #[error("cancelled")]
    Cancelled,
}

/// `Result` with [`Error`].
pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand for an [`Error::InvalidArgument`].
pub fn invalid(name: &'static str, message: impl Into<String>) -> Error {
    Error::InvalidArgument {
        name,
        message: message.into(),
    }
}
