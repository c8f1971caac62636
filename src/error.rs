//! Error type shared by the library. Every variant carries the facts that
//! explain it: the file, the key, the channel, the sample or the DOF.

use std::path::PathBuf;

/// Errors returned by tacit. Numerical trouble that a run can survive
/// (non-convergence, instability, rank deficiency) is *not* an error: it is a
/// status in the result. These are the failures that stop a run.
#[derive(Debug, thiserror::Error)]
pub enum TacitError {
    /// A model file or model value is invalid.
    #[error("model {source_name}: {message}")]
    Model {
        /// File name or "<inline>".
        source_name: String,
        /// What is wrong, naming the key.
        message: String,
    },
    /// A record file is invalid.
    #[error("record {path}: {message}")]
    Record {
        /// The file.
        path: PathBuf,
        /// What is wrong, naming the channel and sample.
        message: String,
    },
    /// An argument or setting is invalid.
    #[error("invalid setting: {0}")]
    Setting(String),
    /// A numerical operation could not be carried out at all (e.g. a singular
    /// mass matrix); recoverable trouble is reported in results instead.
    #[error("numerical failure: {0}")]
    Numerical(String),
    /// I/O failure on a named file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
}

/// Result alias.
pub type Result<T> = std::result::Result<T, TacitError>;

impl TacitError {
    /// Record error helper.
    pub fn record(path: impl Into<PathBuf>, message: impl Into<String>) -> Self {
        TacitError::Record {
            path: path.into(),
            message: message.into(),
        }
    }
    /// Model error helper.
    pub fn model(source_name: impl Into<String>, message: impl Into<String>) -> Self {
        TacitError::Model {
            source_name: source_name.into(),
            message: message.into(),
        }
    }
    /// I/O error helper.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        TacitError::Io {
            path: path.into(),
            source,
        }
    }
}
