//! Scenes: YAML files in `config/`, loaded, checked and turned into a running simulation.

pub mod build;
pub mod config;
mod overrides;
pub mod ply;
pub mod robot_sand;
pub mod run;
pub mod simulation;

use std::path::{Path, PathBuf};

pub use config::SceneConfig;
pub use run::{run_scene, run_scene_observed, NoObserver, Observer, RunOptions, RunSummary};
pub use simulation::{LegWrench, LinkPose, Simulation};

/// A scene that cannot be loaded or built; names the file and the field.
#[derive(thiserror::Error, Debug)]
pub enum SceneError {
    #[error("cannot read scene file {}: {source}", file.display())]
    Read {
        file: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {message}", file.display())]
    Parse { file: PathBuf, message: String },
    #[error("{}: {field}: {message}", file.display())]
    Invalid {
        file: PathBuf,
        field: String,
        message: String,
    },
    #[error(transparent)]
    Robot(#[from] crate::robot::RobotError),
    #[error("--set {assignment}: {message}")]
    Override { assignment: String, message: String },
}

/// A scene loaded from a file, with any `--set key.path=value` overrides applied.
#[derive(Clone, Debug)]
pub struct Scene {
    pub file: PathBuf,
    pub config: SceneConfig,
}

impl Scene {
    /// Reads, parses (unknown keys are errors) and validates a scene file.
    pub fn load(file: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let text = std::fs::read_to_string(file).map_err(|source| SceneError::Read {
            file: file.to_path_buf(),
            source,
        })?;
        Self::from_yaml(&text, file, overrides)
    }

    /// Parses scene text; `file` is only used to name the source in errors.
    pub fn from_yaml(text: &str, file: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let parse_error = |path: String, inner: String| SceneError::Parse {
            file: file.to_path_buf(),
            message: if path == "." {
                inner
            } else {
                format!("{path}: {inner}")
            },
        };
        let config: SceneConfig = if overrides.is_empty() {
            // Straight from the text, so errors carry line and column.
            let de = serde_yaml_ng::Deserializer::from_str(text);
            serde_path_to_error::deserialize(de)
                .map_err(|e| parse_error(e.path().to_string(), e.inner().to_string()))?
        } else {
            let mut value: serde_yaml_ng::Value = serde_yaml_ng::from_str(text)
                .map_err(|e| parse_error(".".into(), e.to_string()))?;
            for assignment in overrides {
                overrides::apply(&mut value, assignment)?;
            }
            serde_path_to_error::deserialize(value)
                .map_err(|e| parse_error(e.path().to_string(), e.inner().to_string()))?
        };
        let scene = Scene {
            file: file.to_path_buf(),
            config,
        };
        scene.validate()?;
        Ok(scene)
    }

    fn invalid(&self, field: impl Into<String>, message: impl Into<String>) -> SceneError {
        SceneError::Invalid {
            file: self.file.clone(),
            field: field.into(),
            message: message.into(),
        }
    }

    /// Checks every value's range and every cross-reference.
    pub fn validate(&self) -> Result<(), SceneError> {
        build::validate(self)
    }
}
