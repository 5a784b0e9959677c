//! Errors of the robot module. Every message names the file and the element at fault.

use std::path::PathBuf;

/// What can go wrong loading, generating or configuring the robot.
#[derive(thiserror::Error, Debug)]
pub enum RobotError {
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The URDF is not well-formed XML or does not follow the URDF schema.
    #[error("{}: malformed URDF: {message}", path.display())]
    UrdfParse {
        /// The URDF file.
        path: PathBuf,
        /// The parser's message.
        message: String,
    },
    /// The URDF parses but describes something this simulator cannot load.
    #[error("{}: {element}: {message}", path.display())]
    UrdfInvalid {
        /// The URDF file.
        path: PathBuf,
        /// The element, e.g. `joint 'leg_front_left_joint'`.
        element: String,
        /// What is wrong with it.
        message: String,
    },
    /// A mesh the URDF references does not exist.
    #[error("{}: link '{link}': mesh '{mesh}' not found (looked for {})", urdf.display(), resolved.display())]
    MeshNotFound {
        /// The URDF file.
        urdf: PathBuf,
        /// The link whose visual or collision element names the mesh.
        link: String,
        /// The file name as written in the URDF.
        mesh: String,
        /// Where it was looked for.
        resolved: PathBuf,
    },
    /// A mesh exists but cannot be read.
    #[error("{}: link '{link}': mesh '{mesh}': {message}", urdf.display())]
    MeshInvalid {
        /// The URDF file.
        urdf: PathBuf,
        /// The link whose visual or collision element names the mesh.
        link: String,
        /// The file name as written in the URDF.
        mesh: String,
        /// What is wrong with it.
        message: String,
    },
    /// A joint the tripod gait drives is absent from the URDF.
    #[error("{}: joint '{joint}' expected by the tripod gait is missing (the URDF has: {available})", path.display())]
    MissingJoint {
        /// The URDF file.
        path: PathBuf,
        /// The missing joint's name.
        joint: String,
        /// The joints the URDF does have, comma-separated.
        available: String,
    },
    /// A configuration value is out of range.
    #[error("{}: {field} = {value}: {reason}", file.display())]
    Config {
        /// The YAML file.
        file: PathBuf,
        /// The field's full key path, e.g. `robot.gait.frequency_hz`.
        field: String,
        /// The value found.
        value: String,
        /// The admissible range.
        reason: String,
    },
    /// A robot-generator parameter is out of range.
    #[error("hexapod parameter {field} = {value}: {reason}")]
    Params {
        /// The parameter's name.
        field: String,
        /// The value given.
        value: f64,
        /// The admissible range.
        reason: String,
    },
}

impl RobotError {
    /// An I/O error on `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Self::Io {
            path: path.into(),
            source,
        }
    }
}
