//! Scenes: YAML files in `config/`, loaded, checked and turned into a running simulation.

pub mod bed;
pub mod build;
pub mod calibration_bed;
pub mod config;
pub mod error;
pub mod memory;
pub(crate) mod overrides;
pub mod ply;
pub mod robot_sand;
pub mod run;
pub mod sand_window;
pub mod simulation;

use std::path::{Path, PathBuf};

use crate::config_error::ConfigError;

pub use calibration_bed::CalibrationError;
pub use config::SceneConfig;
pub use error::{ObserverError, RunError};
pub use run::{
    build_simulation, run_scene, run_scene_observed, run_simulation_observed, NoObserver, Observer,
    RunOptions, RunSummary,
};
pub use simulation::{LinkPose, LinkWrench, Simulation, Terrain, TerrainWrenches};

/// A scene that cannot be loaded or built; names the file and the field.
#[derive(thiserror::Error, Debug)]
pub enum SceneError {
    #[error(transparent)]
    Config(#[from] ConfigError),
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
        let text = ConfigError::read("scene", file)?;
        Self::from_yaml(&text, file, overrides)
    }

    /// Parses scene text; `file` is only used to name the source in errors.
    pub fn from_yaml(text: &str, file: &Path, overrides: &[String]) -> Result<Scene, SceneError> {
        let mut config: SceneConfig = overrides::deserialize_with_overrides(text, overrides)
            .map_err(|e| match e {
                overrides::YamlProblem::Parse(message) => ConfigError::Parse {
                    file: file.to_path_buf(),
                    message,
                }
                .into(),
                overrides::YamlProblem::Override(e) => e,
            })?;
        config
            .terrain
            .rft
            .read_stress_maps()
            .map_err(|e| e.in_file(file))?;
        let scene = Scene {
            file: file.to_path_buf(),
            config,
        };
        scene.validate()?;
        Ok(scene)
    }

    fn invalid(&self, field: impl Into<String>, message: impl Into<String>) -> SceneError {
        ConfigError::Invalid {
            file: self.file.clone(),
            field: field.into(),
            message: message.into(),
        }
        .into()
    }

    /// Checks every value's range and every cross-reference.
    pub fn validate(&self) -> Result<(), SceneError> {
        build::validate(self)
    }
}
