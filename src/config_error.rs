//! The errors of the project's YAML files (scenes, experiments, sweeps): the file cannot be
//! read, does not parse, holds a value out of range, or an output cannot be written. Every one
//! names the file, and an invalid value its field (`sand.dx_m`, `studies.0.vary.1.values.2`).

use std::path::{Path, PathBuf};

/// A file that cannot be used, or an output that cannot be written.
#[derive(thiserror::Error, Debug)]
pub enum ConfigError {
    /// The I/O error is told in the message, not chained as a source, so that a report
    /// of the error with its causes does not tell it twice.
    #[error("cannot read {what} file {}: {error}", file.display())]
    Read {
        /// What the file holds (`scene`, `experiment`, `sweep`), for the message.
        what: &'static str,
        file: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: {message}", file.display())]
    Parse { file: PathBuf, message: String },
    #[error("{}: {field}: {message}", file.display())]
    Invalid {
        file: PathBuf,
        field: String,
        message: String,
    },
    /// As `Read`, the I/O error is in the message only.
    #[error("cannot write {}: {error}", path.display())]
    Write {
        path: PathBuf,
        error: std::io::Error,
    },
}

/// A value out of range, before it is known which file it came from.
#[derive(thiserror::Error, Debug, Clone, PartialEq, Eq)]
#[error("{field}: {message}")]
pub struct FieldError {
    /// The field's path, e.g. `terrain.rft.zeta_n_m3`.
    pub field: String,
    pub message: String,
}

impl FieldError {
    pub fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        FieldError {
            field: field.into(),
            message: message.into(),
        }
    }

    /// The error as found in `file`.
    pub fn in_file(self, file: &Path) -> ConfigError {
        ConfigError::Invalid {
            file: file.to_path_buf(),
            field: self.field,
            message: self.message,
        }
    }
}

impl ConfigError {
    /// Reads `file` as text; an error names it as a `what` file.
    pub fn read(what: &'static str, file: &Path) -> Result<String, ConfigError> {
        std::fs::read_to_string(file).map_err(|error| ConfigError::Read {
            what,
            file: file.to_path_buf(),
            error,
        })
    }

    /// A write error at `path`.
    pub fn write(path: &Path, error: std::io::Error) -> ConfigError {
        ConfigError::Write {
            path: path.to_path_buf(),
            error,
        }
    }
}
