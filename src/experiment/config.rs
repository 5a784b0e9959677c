//! The experiment file (`config/experiments/*.yaml`): a base scene, overrides common to all
//! runs, and the sweep. Every field documents its unit and default; unknown keys are errors,
//! and errors name the file and the field.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::ExperimentError;
use crate::config_error::ConfigError;
use crate::robot::HexapodParams;
use crate::scene::overrides::{deserialize_with_overrides, YamlProblem};
use crate::scene::Scene;

/// The terrain model of a run: the scene's `terrain.model`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TerrainModel {
    /// MLS-MPM sand coupled with CPIC.
    Mpm,
    /// Resistive force theory.
    Rft,
}

impl TerrainModel {
    /// The name in scene and experiment files (`mpm`, `rft`).
    pub fn name(self) -> &'static str {
        match self {
            TerrainModel::Mpm => "mpm",
            TerrainModel::Rft => "rft",
        }
    }

    /// The name for chart titles.
    pub fn label(self) -> &'static str {
        match self {
            TerrainModel::Mpm => "MLS-MPM",
            TerrainModel::Rft => "RFT",
        }
    }
}

/// A whole experiment file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentConfig {
    /// Names the outputs (`out/experiments/<name>-<stamp>`): letters, digits, `_`, `-`, `.`.
    pub name: String,
    /// The scene every run starts from, relative to the working directory like every path of
    /// a scene. Default `config/robot_on_sand.yaml`.
    #[serde(default = "default_base_scene")]
    pub base_scene: PathBuf,
    /// `--set`-style `key.path=value` changes to the base scene, common to all runs (e.g.
    /// `sand.dx_m=0.0125`). Default none.
    #[serde(default)]
    pub overrides: Vec<String>,
    /// Leg curvatures 1/r in units of 1/R (R = half the chord): 1 = C-leg, -1 = reversed,
    /// 0 = straight; each in [-1, 1]. Default [-1, -0.5, 0, 0.5, 1].
    #[serde(default = "default_curvatures")]
    pub curvatures_per_r: Vec<f64>,
    /// Gait (leg rotation) frequencies (Hz), each > 0. Default [1, 2].
    #[serde(default = "default_frequencies")]
    pub frequencies_hz: Vec<f64>,
    /// Terrain models (`mpm`, `rft`): the scene's `terrain.model`. Default [mpm, rft].
    #[serde(default = "default_terrain_models")]
    pub terrain_models: Vec<TerrainModel>,
    /// Runs per cell (curvature, frequency, model), the robot started `start_spacing_m`
    /// further along x each time from where the base scene (with `overrides`) starts it. The
    /// walk is chaotic, so one run's speed is one sample; `summary.csv` pools the starts.
    /// >= 1. Default 1.
    #[serde(default = "default_starts")]
    pub starts: u32,
    /// x spacing of the starts (m), > 0. Default 0.002 (as `sandstep sweep`).
    #[serde(default = "default_start_spacing_m")]
    pub start_spacing_m: f64,
    /// Simulated time to settle before measuring (s), >= 0: the measured cycles are the first
    /// that start at or after it ([`Experiment::measure_from_s`]). Default 0.5.
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    /// Gait cycles measured after settling, >= 1. Default 4.
    #[serde(default = "default_cycles")]
    pub cycles: u32,
    /// Total robot mass, legs included (kg); the generator gives the body what the legs leave,
    /// so every curvature walks at this mass. Default 0.085 (the published 85 g).
    #[serde(default = "default_total_mass_kg")]
    pub robot_total_mass_kg: f64,
}

/// Checks that `name` can name an output folder or file: letters, digits, `_`, `-`, `.`
/// (not first).
pub fn check_output_name(name: &str) -> Result<(), UnsafeName> {
    let safe = |ch: char| ch.is_ascii_alphanumeric() || "_-.".contains(ch);
    if name.is_empty() || !name.chars().all(safe) || name.starts_with('.') {
        return Err(UnsafeName(name.to_string()));
    }
    Ok(())
}

/// A name that cannot name an output folder or file ([`check_output_name`]).
#[derive(thiserror::Error, Debug, Clone, PartialEq, Eq)]
#[error("'{0}' must be letters, digits, '_', '-' or '.' (not first)")]
pub struct UnsafeName(pub String);

/// Settling times within this many gait cycles above a whole number of cycles round down.
const SETTLE_ROUNDING_TOLERANCE: f64 = 1e-9;

/// The measurement starts this many gait cycles before the first cycle boundary after
/// settling: a leg may reach its boundary a little before the gait does.
pub const LEAD_CYCLES: f64 = 0.25;

/// The measured window is this many gait cycles longer than the measured cycles: a quarter
/// cycle before them ([`LEAD_CYCLES`]), and a quarter after, as the legs may lag the gait. The
/// window is `cycles + 1/2` cycles, a whole number of tripod steps.
pub const WINDOW_EXTRA_CYCLES: f64 = 0.5;

/// The measured stretch of a walking run: `cycles` whole gait cycles after settling, with a
/// quarter cycle ([`LEAD_CYCLES`]) before them and one after ([`WINDOW_EXTRA_CYCLES`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitWindow {
    /// Start of the measurement (s): a quarter cycle before the first leg cycle boundary at or
    /// after the settling time (the gait's boundaries are at whole cycles), and not before 0.
    pub from_s: f64,
    /// End of the measurement and of the run (s): `from_s + (cycles + 1/2) / f`.
    pub until_s: f64,
}

impl GaitWindow {
    /// The window of `cycles` cycles at `frequency_hz` after `settle_s` of settling.
    pub fn after_settling(settle_s: f64, cycles: u32, frequency_hz: f64) -> Self {
        let whole_cycles = (settle_s * frequency_hz - SETTLE_ROUNDING_TOLERANCE).ceil();
        let from_s = (whole_cycles - LEAD_CYCLES).max(0.0) / frequency_hz;
        GaitWindow {
            from_s,
            until_s: from_s + (cycles as f64 + WINDOW_EXTRA_CYCLES) / frequency_hz,
        }
    }
}

fn default_base_scene() -> PathBuf {
    PathBuf::from("config/robot_on_sand.yaml")
}
fn default_curvatures() -> Vec<f64> {
    vec![-1.0, -0.5, 0.0, 0.5, 1.0]
}
fn default_frequencies() -> Vec<f64> {
    vec![1.0, 2.0]
}
fn default_terrain_models() -> Vec<TerrainModel> {
    vec![TerrainModel::Mpm, TerrainModel::Rft]
}
fn default_starts() -> u32 {
    1
}
fn default_start_spacing_m() -> f64 {
    0.002
}
fn default_settle_s() -> f64 {
    0.5
}
fn default_cycles() -> u32 {
    4
}
fn default_total_mass_kg() -> f64 {
    crate::robot::HexapodParams::default().total_mass_kg
}

/// An experiment loaded from a file, with any `--set` overrides applied, and checked.
#[derive(Clone, Debug)]
pub struct Experiment {
    pub file: PathBuf,
    pub config: ExperimentConfig,
    /// Where each start puts the robot along x (m): `starts` values `start_spacing_m` apart
    /// from the base scene's start.
    pub start_x_m: Vec<f64>,
}

impl Experiment {
    /// Reads, parses (unknown keys are errors) and validates an experiment file. `overrides`
    /// are `key.path=value` changes to the experiment file itself (e.g. `cycles=2`).
    pub fn load(file: &Path, overrides: &[String]) -> Result<Self, ExperimentError> {
        let text = ConfigError::read("experiment", file)?;
        Self::from_yaml(&text, file, overrides)
    }

    /// Parses experiment text; `file` names the source in errors. Checks the values and that
    /// the base scene loads with the common overrides; does not look for URDFs.
    pub fn from_yaml(
        text: &str,
        file: &Path,
        overrides: &[String],
    ) -> Result<Self, ExperimentError> {
        let config: ExperimentConfig =
            deserialize_with_overrides(text, overrides).map_err(|e| ConfigError::Parse {
                file: file.to_path_buf(),
                message: match e {
                    YamlProblem::Parse(message) => message,
                    YamlProblem::Override(e) => e.to_string(),
                },
            })?;
        let mut experiment = Experiment {
            file: file.to_path_buf(),
            config,
            start_x_m: Vec::new(),
        };
        experiment.start_x_m = experiment.validate()?;
        Ok(experiment)
    }

    fn invalid(&self, field: impl Into<String>, message: impl Into<String>) -> ExperimentError {
        ConfigError::Invalid {
            file: self.file.clone(),
            field: field.into(),
            message: message.into(),
        }
        .into()
    }

    /// Checks every value, that the base scene with the common overrides is a robot scene, and
    /// that every start loads with every terrain model; returns the starts' x (m).
    // Negated comparisons (`!(a <= b)`) on purpose: they reject NaN too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    pub fn validate(&self) -> Result<Vec<f64>, ExperimentError> {
        let c = &self.config;
        check_output_name(&c.name).map_err(|e| self.invalid("name", e.to_string()))?;
        let list = |field: &str, values: &[f64], check: &dyn Fn(f64) -> bool, range: &str| {
            if values.is_empty() {
                return Err(self.invalid(field, "needs at least one value"));
            }
            for (i, &v) in values.iter().enumerate() {
                if !check(v) {
                    return Err(
                        self.invalid(format!("{field}.{i}"), format!("{v} must be {range}"))
                    );
                }
                if values[..i].contains(&v) {
                    return Err(
                        self.invalid(format!("{field}.{i}"), format!("{v} is listed twice"))
                    );
                }
            }
            Ok(())
        };
        list(
            "curvatures_per_r",
            &c.curvatures_per_r,
            &|k| (-1.0..=1.0).contains(&k),
            "in [-1, 1] (units of 1/R)",
        )?;
        list(
            "frequencies_hz",
            &c.frequencies_hz,
            &|f| f > 0.0 && f.is_finite(),
            "a finite number > 0 (Hz)",
        )?;
        if c.terrain_models.is_empty() {
            return Err(self.invalid("terrain_models", "needs at least one of mpm, rft"));
        }
        for (i, m) in c.terrain_models.iter().enumerate() {
            if c.terrain_models[..i].contains(m) {
                return Err(self.invalid(
                    format!("terrain_models.{i}"),
                    format!("{} is listed twice", m.name()),
                ));
            }
        }
        if !(c.settle_s >= 0.0 && c.settle_s.is_finite()) {
            return Err(self.invalid(
                "settle_s",
                format!("{} must be a finite number >= 0 (s)", c.settle_s),
            ));
        }
        if c.cycles == 0 {
            return Err(self.invalid("cycles", "must be at least 1"));
        }
        if c.starts == 0 {
            return Err(self.invalid("starts", "must be at least 1"));
        }
        if !(c.start_spacing_m > 0.0 && c.start_spacing_m.is_finite()) {
            return Err(self.invalid(
                "start_spacing_m",
                format!("{} must be a finite number > 0 (m)", c.start_spacing_m),
            ));
        }
        if !(c.robot_total_mass_kg > 0.0 && c.robot_total_mass_kg.is_finite()) {
            return Err(self.invalid(
                "robot_total_mass_kg",
                format!("{} must be a finite number > 0 (kg)", c.robot_total_mass_kg),
            ));
        }
        for &k in &c.curvatures_per_r {
            if let Err((field, value, reason)) = self.robot_params(k).validate() {
                return Err(self.invalid(
                    "robot_total_mass_kg",
                    format!("at curvature {k}: the robot's {field} would be {value}: {reason}"),
                ));
            }
        }
        let scene = Scene::load(&c.base_scene, &c.overrides).map_err(|e| {
            let field = if matches!(e, crate::scene::SceneError::Override { .. }) {
                "overrides"
            } else {
                "base_scene"
            };
            self.invalid(field, e.to_string())
        })?;
        let Some(robot) = &scene.config.robot else {
            return Err(self.invalid(
                "base_scene",
                format!("{} has no `robot` section", c.base_scene.display()),
            ));
        };
        let start_x_m = start_positions_m(
            robot.initial_pose.position_m[0],
            c.starts,
            c.start_spacing_m,
        );
        // Each start must load with each model (an MPM robot must start over the sand).
        for (i, &x) in start_x_m.iter().enumerate() {
            for &model in &c.terrain_models {
                let mut overrides = c.overrides.clone();
                overrides.extend([start_override(x), model_override(model)]);
                Scene::load(&c.base_scene, &overrides).map_err(|e| {
                    self.invalid(
                        "starts",
                        format!("start {i} (x = {x} m, {}): {e}", model.name()),
                    )
                })?;
            }
        }
        Ok(start_x_m)
    }

    /// The robot with legs of `curvature_per_r` (units of 1/R): the published robot's legs
    /// and the experiment's total mass (`robot_total_mass_kg`).
    pub fn robot_params(&self, curvature_per_r: f64) -> HexapodParams {
        HexapodParams {
            total_mass_kg: self.config.robot_total_mass_kg,
            ..HexapodParams::default()
        }
        .with_curvature(curvature_per_r)
    }

    /// When the measurement of a run at `frequency_hz` starts (s): a quarter cycle
    /// ([`LEAD_CYCLES`]) before the first leg cycle boundary at or after `settle_s` (the gait's
    /// boundaries are at whole cycles, leg angle a multiple of 2 pi), and not before 0.
    pub fn measure_from_s(&self, frequency_hz: f64) -> f64 {
        GaitWindow::after_settling(self.config.settle_s, self.config.cycles, frequency_hz).from_s
    }

    /// Simulated time of a run at `frequency_hz` (s):
    /// `measure_from_s + (cycles + WINDOW_EXTRA_CYCLES) / f`.
    pub fn run_duration_s(&self, frequency_hz: f64) -> f64 {
        GaitWindow::after_settling(self.config.settle_s, self.config.cycles, frequency_hz).until_s
    }

    /// Every run of the sweep: by terrain model, then frequency, then curvature, then start.
    pub fn runs(&self) -> Vec<RunSpec> {
        let c = &self.config;
        let mut runs = Vec::new();
        for &terrain_model in &c.terrain_models {
            for &frequency_hz in &c.frequencies_hz {
                for &curvature_per_r in &c.curvatures_per_r {
                    for (start, &start_x_m) in self.start_x_m.iter().enumerate() {
                        let mut name = format!(
                            "k{}_f{}hz_{}",
                            number(curvature_per_r),
                            number(frequency_hz),
                            terrain_model.name()
                        );
                        if self.start_x_m.len() > 1 {
                            name.push_str(&format!("_start{start}"));
                        }
                        runs.push(RunSpec {
                            name,
                            curvature_per_r,
                            frequency_hz,
                            terrain_model,
                            start_x_m,
                            measure_from_s: self.measure_from_s(frequency_hz),
                            duration_s: self.run_duration_s(frequency_hz),
                        });
                    }
                }
            }
        }
        runs
    }
}

/// Where `starts` runs start along x (m): `spacing_m` apart from `x0_m`. Shared with
/// `sandstep sweep`.
pub fn start_positions_m(x0_m: f64, starts: u32, spacing_m: f64) -> Vec<f64> {
    (0..starts)
        .map(|k| x0_m + f64::from(k) * spacing_m)
        .collect()
}

/// The `--set` override that starts the robot at `x_m` along x.
pub fn start_override(x_m: f64) -> String {
    format!("robot.initial_pose.position_m.0={x_m}")
}

/// The `--set` override that selects `model`.
pub fn model_override(model: TerrainModel) -> String {
    format!("terrain.model={}", model.name())
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// `k<curvature>_f<frequency>hz_<model>`, e.g. `k-0.5_f2hz_mpm`, with `_start<i>` (i from
    /// 0) when there are several starts: names its bag folder.
    pub name: String,
    pub curvature_per_r: f64,
    pub frequency_hz: f64,
    pub terrain_model: TerrainModel,
    /// Where the robot starts along x (m).
    pub start_x_m: f64,
    /// Start of the measurement (s): [`Experiment::measure_from_s`].
    pub measure_from_s: f64,
    /// Simulated time (s).
    pub duration_s: f64,
}

/// `x` as the shortest decimal that reads back to it, without a negative zero: `-0.5`, `1`.
pub fn number(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::experiment::ExperimentError;

    const FILE: &str = "config/experiments/test.yaml";

    fn load(text: &str, overrides: &[&str]) -> Result<Experiment, ExperimentError> {
        let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
        Experiment::from_yaml(text, Path::new(FILE), &overrides)
    }

    /// The error message of an experiment that must not load.
    fn error(text: &str, overrides: &[&str]) -> String {
        load(text, overrides).unwrap_err().to_string()
    }

    #[test]
    fn defaults_fill_everything_but_the_name() {
        let e = load("name: sweep\n", &[]).unwrap();
        let c = &e.config;
        assert_eq!(c.base_scene, PathBuf::from("config/robot_on_sand.yaml"));
        assert!(c.overrides.is_empty());
        assert_eq!(c.curvatures_per_r, [-1.0, -0.5, 0.0, 0.5, 1.0]);
        assert_eq!(c.frequencies_hz, [1.0, 2.0]);
        assert_eq!(c.terrain_models, [TerrainModel::Mpm, TerrainModel::Rft]);
        assert_eq!((c.settle_s, c.cycles), (0.5, 4));
        assert_eq!((c.starts, c.start_spacing_m), (1, 0.002));
        assert_eq!(e.start_x_m, [0.0]);
        assert!((c.robot_total_mass_kg - 0.085).abs() < 1e-15);
        assert!(error("curvatures_per_r: [1]\n", &[]).contains("name"));
    }

    #[test]
    fn the_shipped_experiment_loads() {
        let e = Experiment::load(Path::new("config/experiments/leg_curvature.yaml"), &[]).unwrap();
        assert_eq!(e.config.name, "leg_curvature");
        assert_eq!(e.runs().len(), 5 * 3 * 2 * 3);
    }

    #[test]
    fn runs_sweep_models_then_frequencies_then_curvatures() {
        let e = load(
            "name: s\ncurvatures_per_r: [-1, 0.5]\nfrequencies_hz: [1, 2.5]\nsettle_s: 0.5\n\
             cycles: 3\nterrain_models: [rft, mpm]\n",
            &[],
        )
        .unwrap();
        let runs = e.runs();
        let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "k-1_f1hz_rft",
                "k0.5_f1hz_rft",
                "k-1_f2.5hz_rft",
                "k0.5_f2.5hz_rft",
                "k-1_f1hz_mpm",
                "k0.5_f1hz_mpm",
                "k-1_f2.5hz_mpm",
                "k0.5_f2.5hz_mpm",
            ]
        );
        // Settling rounds up to whole cycles (1 s at 1 Hz, 0.8 s = 2 cycles at 2.5 Hz), the
        // measurement starts a quarter cycle earlier and lasts 3.5 cycles.
        assert!((runs[0].measure_from_s - 0.75).abs() < 1e-12);
        assert!((runs[0].duration_s - 4.25).abs() < 1e-12);
        assert!((runs[2].measure_from_s - 0.7).abs() < 1e-12);
        assert!((runs[2].duration_s - 2.1).abs() < 1e-12);
        // Exactly on a cycle boundary: no rounding up.
        let on_grid = load("name: s\nsettle_s: 0.5\nfrequencies_hz: [2]\n", &[]).unwrap();
        assert!((on_grid.measure_from_s(2.0) - 0.375).abs() < 1e-12);
        assert!((on_grid.run_duration_s(2.0) - 2.625).abs() < 1e-12);
        // No settling: from the start, where the first cycle begins.
        let zero = load("name: s\nsettle_s: 0\n", &[]).unwrap();
        assert_eq!(zero.measure_from_s(1.0), 0.0);
        assert!((zero.run_duration_s(1.0) - 4.5).abs() < 1e-12);
        assert_eq!(number(-0.0), "0");
        assert!(runs.iter().all(|r| r.start_x_m == 0.0));
    }

    #[test]
    fn each_start_repeats_every_run() {
        let e = load(
            "name: s\ncurvatures_per_r: [1]\nfrequencies_hz: [2, 4]\nterrain_models: [mpm]\n\
             starts: 2\nstart_spacing_m: 0.004\n\
             overrides: [robot.initial_pose.position_m.0=0.05]\n",
            &[],
        )
        .unwrap();
        let runs = e.runs();
        let named: Vec<(&str, f64)> = runs
            .iter()
            .map(|r| (r.name.as_str(), r.start_x_m))
            .collect();
        assert_eq!(
            named,
            [
                ("k1_f2hz_mpm_start0", 0.05),
                ("k1_f2hz_mpm_start1", 0.05 + 0.004),
                ("k1_f4hz_mpm_start0", 0.05),
                ("k1_f4hz_mpm_start1", 0.05 + 0.004),
            ]
        );
    }

    #[test]
    fn errors_name_the_file_and_the_field() {
        let cases: [(&str, &[&str], &str); 17] = [
            ("name: s\nstarts: 0\n", &[], "starts: must be at least 1"),
            (
                "name: s\nstart_spacing_m: 0\n",
                &[],
                "start_spacing_m: 0 must be a finite number > 0 (m)",
            ),
            (
                "name: s\nstarts: 3\nstart_spacing_m: 0.5\n",
                &[],
                "starts: start 2 (x = 1 m, mpm): config/robot_on_sand.yaml: \
                 robot.initial_pose.position_m[0]",
            ),
            ("name: s\nspeed: 1\n", &[], "unknown field `speed`"),
            ("name: a/b\n", &[], "name:"),
            (
                "name: s\ncurvatures_per_r: [0, 1.5]\n",
                &[],
                "curvatures_per_r.1: 1.5 must be in [-1, 1]",
            ),
            (
                "name: s\ncurvatures_per_r: []\n",
                &[],
                "curvatures_per_r: needs at least one value",
            ),
            (
                "name: s\ncurvatures_per_r: [1, 1]\n",
                &[],
                "curvatures_per_r.1: 1 is listed twice",
            ),
            (
                "name: s\nfrequencies_hz: [2, -1]\n",
                &[],
                "frequencies_hz.1: -1 must be a finite number > 0",
            ),
            ("name: s\nfrequencies_hz: [.nan]\n", &[], "frequencies_hz.0"),
            (
                "name: s\nterrain_models: [mpm, dem]\n",
                &[],
                "terrain_models[1]: unknown variant `dem`",
            ),
            (
                "name: s\nterrain_models: [rft, rft]\n",
                &[],
                "terrain_models.1: rft is listed twice",
            ),
            (
                "name: s\nsettle_s: -1\n",
                &[],
                "settle_s: -1 must be a finite number >= 0",
            ),
            ("name: s\ncycles: 0\n", &[], "cycles: must be at least 1"),
            (
                "name: s\nrobot_total_mass_kg: 0.005\n",
                &[],
                "robot_total_mass_kg: at curvature -1",
            ),
            (
                "name: s\nbase_scene: config/none.yaml\n",
                &[],
                "base_scene: cannot read scene file config/none.yaml",
            ),
            (
                "name: s\n",
                &["overrides=[sand.dx_m=-1]"],
                "base_scene: config/robot_on_sand.yaml: sand.dx_m",
            ),
        ];
        for (text, overrides, expected) in cases {
            let message = error(text, overrides);
            assert!(
                message.starts_with(FILE) && message.contains(expected),
                "{text:?} {overrides:?}: {message}"
            );
        }
        assert!(
            error("name: s\nbase_scene: config/column_collapse.yaml\n", &[])
                .contains("base_scene: config/column_collapse.yaml has no `robot` section")
        );
        assert!(error("name: s\n", &["overrides=[novalue]"]).contains("overrides: --set novalue"));
        assert!(error("name: s\n", &["cycles"]).contains("--set cycles: expected key.path=value"));
    }

    #[test]
    fn set_changes_the_experiment() {
        let e = load(
            "name: s\n",
            &[
                "cycles=2",
                "terrain_models=[mpm]",
                "overrides.0=sand.dx_m=0.025",
            ],
        );
        // `overrides.0` on an absent list: the parent is created as a map, which is rejected.
        assert!(e.is_err());
        let e = load(
            "name: s\noverrides: [sand.dx_m=0.0125]\n",
            &[
                "cycles=2",
                "terrain_models=[mpm]",
                "overrides.0=sand.dx_m=0.025",
            ],
        )
        .unwrap();
        assert_eq!(e.config.cycles, 2);
        assert_eq!(e.config.terrain_models, [TerrainModel::Mpm]);
        assert_eq!(e.config.overrides, ["sand.dx_m=0.025"]);
    }

    #[test]
    fn urdf_arguments_keep_the_total_mass() {
        let e = load("name: s\nrobot_total_mass_kg: 0.1\n", &[]).unwrap();
        for k in [-1.0, 0.0, 0.5] {
            let p = e.robot_params(k);
            assert!((p.total_mass_kg - 0.1).abs() < 1e-15);
            assert!(
                (p.legs.curvature_per_m - k / p.legs.half_chord_m()).abs() < 1e-9,
                "{k}"
            );
        }
    }
}
