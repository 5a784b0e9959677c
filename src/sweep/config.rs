//! The sweep file (`config/sweeps/*.yaml`): studies, each a base scene, a quantity of interest
//! and the settings to try. Every field documents its unit and default; unknown keys are
//! errors, and errors name the file and the field (`studies.0.vary.1.values.2`).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::{SweepError, SETTINGS_DIR};
use crate::config_error::ConfigError;
use crate::experiment::config::{check_output_name, start_override, start_positions_m, GaitWindow};
use crate::scene::overrides::{deserialize_with_overrides, YamlProblem};
use crate::scene::Scene;

/// What a study measures, and what its error is taken against.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// The robot's mean speed along x over `cycles` gait cycles after `settle_s` (m/s), against
    /// the study's `reference` setting (the finest run).
    RobotSpeed,
    /// The column collapse's normalized runout `(L_inf - L_i) / L_i`, against the published law
    /// of Lube et al. 2005 (`1.2 a` for a < 1.8, `1.9 a^(2/3)` above 2.8).
    CollapseRunout,
}

impl Quantity {
    /// The name in sweep files and results.
    pub fn name(self) -> &'static str {
        match self {
            Quantity::RobotSpeed => "robot_speed",
            Quantity::CollapseRunout => "collapse_runout",
        }
    }

    /// What the error is taken against, for chart labels.
    pub fn error_label(self) -> &'static str {
        match self {
            Quantity::RobotSpeed => {
                "relative error of the robot's mean speed against the reference run"
            }
            Quantity::CollapseRunout => {
                "relative error of the normalized runout against Lube et al. 2005"
            }
        }
    }
}

/// A whole sweep file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepConfig {
    /// Names the outputs (`out/sweeps/<name>-<stamp>`): letters, digits, `_`, `-`, `.`.
    pub name: String,
    /// The studies, run in order; at least one.
    pub studies: Vec<StudyConfig>,
}

/// One scene swept over its settings, one quantity measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyConfig {
    /// Names the study's rows and chart (`<name>.png`): letters, digits, `_`, `-`, `.`.
    pub name: String,
    /// The scene every setting starts from, relative to the working directory.
    pub base_scene: PathBuf,
    /// `--set`-style `key.path=value` changes common to all settings (the baseline's values).
    /// Default none.
    #[serde(default)]
    pub overrides: Vec<String>,
    /// What is measured: `robot_speed` or `collapse_runout`.
    pub quantity: Quantity,
    /// Changes that make the reference run, the finest setting, against which `robot_speed`
    /// errors are taken (required there; not allowed for `collapse_runout`, whose reference
    /// is the published law).
    #[serde(default)]
    pub reference: Option<Vec<String>>,
    /// Whether the baseline (the base scene with `overrides` only) is a setting. Default true.
    #[serde(default = "default_true")]
    pub baseline: bool,
    /// One parameter at a time: each value of each axis is a setting, the baseline otherwise.
    /// Default none.
    #[serde(default)]
    pub vary: Vec<Axis>,
    /// Named settings that change several parameters at once. Default none.
    #[serde(default)]
    pub settings: Vec<NamedSetting>,
    /// `robot_speed`: simulated time to settle before the measured cycles (s), >= 0.
    /// Default 0.5.
    #[serde(default = "default_settle_s")]
    pub settle_s: f64,
    /// `robot_speed`: gait cycles measured after settling, >= 1. Default 2.
    #[serde(default = "default_cycles")]
    pub cycles: u32,
    /// `robot_speed`: runs per setting, the robot started `start_spacing_m` further along x
    /// each time; the setting's value is their mean, their spread its noise (the speed over a
    /// few cycles is chaotic: `docs/speed-vs-accuracy.md`). >= 1. Default 1.
    #[serde(default = "default_starts")]
    pub starts: u32,
    /// `robot_speed`: x spacing of the starts (m), > 0. Default 0.002.
    #[serde(default = "default_start_spacing")]
    pub start_spacing_m: f64,
}

/// A scene parameter and the values it takes, one setting each.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Axis {
    /// Names the axis's settings, `<name>=<value>`. Default: the key's last part (e.g.
    /// `dx_m` for `sand.dx_m`).
    #[serde(default)]
    pub name: Option<String>,
    /// The scene key, as for `--set` (e.g. `sand.dx_m`, `sand.bodies.0.particles_per_cell`).
    pub key: String,
    /// Its values (numbers or words, e.g. `rft`); at least one, none twice. List values other
    /// than the baseline's: the baseline is a setting of its own.
    pub values: Vec<serde_yaml_ng::Value>,
}

/// A setting with a name of its own.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedSetting {
    /// Its name in the results: letters, digits, `_`, `-`, `.`.
    pub name: String,
    /// Its `--set`-style changes on top of the study's `overrides`.
    pub overrides: Vec<String>,
}

fn default_true() -> bool {
    true
}
fn default_settle_s() -> f64 {
    0.5
}
fn default_cycles() -> u32 {
    2
}
fn default_starts() -> u32 {
    1
}
fn default_start_spacing() -> f64 {
    0.002
}

/// The name of the reference setting in the results.
pub const REFERENCE_SETTING: &str = "reference";
/// The name of the baseline setting in the results.
pub const BASELINE_SETTING: &str = "baseline";

/// One run of a study: the base scene with the study's and the setting's overrides.
#[derive(Clone, Debug, PartialEq)]
pub struct Setting {
    /// Index of the study in the sweep.
    pub study: usize,
    /// `reference`, `baseline`, `<axis name>=<value>` or a named setting's name.
    pub name: String,
    /// The setting's own changes (the study's `overrides` come first).
    pub overrides: Vec<String>,
    /// Whether this is the study's reference run.
    pub is_reference: bool,
    /// The field of the sweep file it comes from, for errors.
    pub field: String,
    /// Simulated time of the run (s).
    pub duration_s: f64,
    /// `robot_speed`: the measured window.
    pub window: Option<GaitWindow>,
    /// `robot_speed`: the robot's start x of each run (m); empty for other quantities (one
    /// run, the scene as it is).
    pub start_x_m: Vec<f64>,
}

impl Setting {
    /// Runs of the setting: one per start, at least one.
    pub fn runs(&self) -> usize {
        self.start_x_m.len().max(1)
    }
}

/// A sweep file, loaded and checked.
#[derive(Clone, Debug)]
pub struct Sweep {
    pub file: PathBuf,
    pub config: SweepConfig,
    /// Every setting of every study, in run order: per study the reference first.
    pub settings: Vec<Setting>,
}

/// `value` as a `--set` value: YAML text on one line.
fn scalar_text(value: &serde_yaml_ng::Value) -> String {
    match value {
        serde_yaml_ng::Value::String(s) => s.clone(),
        other => serde_yaml_ng::to_string(other)
            .map(|s| s.trim_end().to_string())
            .unwrap_or_default(),
    }
}

impl Sweep {
    /// Reads, parses and checks a sweep file, loading every setting's scene.
    pub fn load(file: &Path) -> Result<Self, SweepError> {
        let text = ConfigError::read("sweep", file)?;
        Self::from_yaml(&text, file)
    }

    /// Parses sweep text; `file` names the source in errors.
    pub fn from_yaml(text: &str, file: &Path) -> Result<Self, SweepError> {
        let config: SweepConfig =
            deserialize_with_overrides(text, &[]).map_err(|e| ConfigError::Parse {
                file: file.to_path_buf(),
                message: match e {
                    YamlProblem::Parse(message) => message,
                    YamlProblem::Override(e) => e.to_string(),
                },
            })?;
        let mut sweep = Sweep {
            file: file.to_path_buf(),
            config,
            settings: Vec::new(),
        };
        sweep.settings = sweep.expand()?;
        Ok(sweep)
    }

    fn invalid(&self, field: impl Into<String>, message: impl Into<String>) -> SweepError {
        ConfigError::Invalid {
            file: self.file.clone(),
            field: field.into(),
            message: message.into(),
        }
        .into()
    }

    /// Only the studies named in `names` (all if empty); an unknown name is an error.
    pub fn only_studies(mut self, names: &[String]) -> Result<Self, SweepError> {
        if names.is_empty() {
            return Ok(self);
        }
        for name in names {
            if !self.config.studies.iter().any(|s| &s.name == name) {
                let known: Vec<&str> = self
                    .config
                    .studies
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect();
                return Err(self.invalid(
                    "studies",
                    format!("no study named '{name}' (there are {known:?})"),
                ));
            }
        }
        let keep: Vec<bool> = self
            .config
            .studies
            .iter()
            .map(|s| names.contains(&s.name))
            .collect();
        self.settings.retain(|s| keep[s.study]);
        Ok(self)
    }

    /// `study/setting`: a setting's name in `--list`, `--run` and the progress lines.
    pub fn label(&self, setting: &Setting) -> String {
        format!(
            "{}/{}",
            self.config.studies[setting.study].name, setting.name
        )
    }

    /// Every setting's [`Sweep::label`], in order.
    pub fn labels(&self) -> Vec<String> {
        self.settings.iter().map(|s| self.label(s)).collect()
    }

    /// Where setting `index` leaves its record under `out`: `settings/<study>/<n>.json`, `n`
    /// its place in its study (from 0), the same whichever studies are run.
    pub fn record_path(&self, out: &Path, index: usize) -> PathBuf {
        let setting = &self.settings[index];
        let place = self.settings[..index]
            .iter()
            .filter(|s| s.study == setting.study)
            .count();
        out.join(SETTINGS_DIR)
            .join(&self.config.studies[setting.study].name)
            .join(format!("{place:03}.json"))
    }

    /// The scene of `setting`.
    pub fn scene(&self, setting: &Setting) -> Result<Scene, crate::scene::SceneError> {
        self.scene_of_run(setting, None)
    }

    /// The scene of run `run` of `setting` (its start, [`Setting::start_x_m`]), or of the
    /// setting as it is for None.
    pub fn scene_of_run(
        &self,
        setting: &Setting,
        run: Option<usize>,
    ) -> Result<Scene, crate::scene::SceneError> {
        let study = &self.config.studies[setting.study];
        let start = run
            .and_then(|r| setting.start_x_m.get(r))
            .map(|&x| start_override(x));
        let overrides: Vec<String> = study
            .overrides
            .iter()
            .chain(&setting.overrides)
            .cloned()
            .chain(start)
            .collect();
        Scene::load(&study.base_scene, &overrides)
    }

    /// Checks the studies and lists their settings, each scene loaded and checked against the
    /// study's quantity.
    // Negated comparisons (`!(a >= b)`) on purpose: they reject NaN too.
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    fn expand(&self) -> Result<Vec<Setting>, SweepError> {
        let c = &self.config;
        check_output_name(&c.name).map_err(|e| self.invalid("name", e.to_string()))?;
        if c.studies.is_empty() {
            return Err(self.invalid("studies", "needs at least one study"));
        }
        let mut settings = Vec::new();
        for (i, study) in c.studies.iter().enumerate() {
            let at = |field: &str| format!("studies.{i}.{field}");
            check_output_name(&study.name).map_err(|e| self.invalid(at("name"), e.to_string()))?;
            if c.studies[..i].iter().any(|s| s.name == study.name) {
                return Err(self.invalid(at("name"), format!("'{}' names two studies", study.name)));
            }
            match (study.quantity, &study.reference) {
                (Quantity::RobotSpeed, None) => {
                    return Err(self.invalid(
                        at("reference"),
                        "robot_speed needs the changes of its reference (finest) run",
                    ))
                }
                (Quantity::CollapseRunout, Some(_)) => {
                    return Err(self.invalid(
                        at("reference"),
                        "collapse_runout is measured against the published law; remove `reference`",
                    ))
                }
                _ => {}
            }
            if !(study.settle_s >= 0.0 && study.settle_s.is_finite()) {
                return Err(self.invalid(
                    at("settle_s"),
                    format!("{} must be a finite number >= 0 (s)", study.settle_s),
                ));
            }
            if study.cycles == 0 {
                return Err(self.invalid(at("cycles"), "must be at least 1"));
            }
            if study.starts == 0 {
                return Err(self.invalid(at("starts"), "must be at least 1"));
            }
            if !(study.start_spacing_m > 0.0 && study.start_spacing_m.is_finite()) {
                return Err(self.invalid(
                    at("start_spacing_m"),
                    format!(
                        "{} must be a finite distance > 0 (m)",
                        study.start_spacing_m
                    ),
                ));
            }
            let mut candidates: Vec<(String, Vec<String>, bool, String)> = Vec::new();
            if let Some(reference) = &study.reference {
                candidates.push((
                    REFERENCE_SETTING.into(),
                    reference.clone(),
                    true,
                    at("reference"),
                ));
            }
            if study.baseline {
                candidates.push((BASELINE_SETTING.into(), Vec::new(), false, at("baseline")));
            }
            for (a, axis) in study.vary.iter().enumerate() {
                if axis.values.is_empty() {
                    return Err(
                        self.invalid(at(&format!("vary.{a}.values")), "needs at least one value")
                    );
                }
                let axis_name = axis
                    .name
                    .clone()
                    .unwrap_or_else(|| axis.key.rsplit('.').next().unwrap_or_default().into());
                for (v, value) in axis.values.iter().enumerate() {
                    let value = scalar_text(value);
                    candidates.push((
                        format!("{axis_name}={value}"),
                        vec![format!("{}={value}", axis.key)],
                        false,
                        at(&format!("vary.{a}.values.{v}")),
                    ));
                }
            }
            for (n, named) in study.settings.iter().enumerate() {
                check_output_name(&named.name)
                    .map_err(|e| self.invalid(at(&format!("settings.{n}.name")), e.to_string()))?;
                candidates.push((
                    named.name.clone(),
                    named.overrides.clone(),
                    false,
                    at(&format!("settings.{n}")),
                ));
            }
            if candidates.iter().all(|c| c.2) || candidates.is_empty() {
                return Err(self.invalid(
                    at("vary"),
                    "no setting to measure: give `vary` or `settings`, or keep `baseline`",
                ));
            }
            let study_start = settings.len();
            for (name, overrides, is_reference, field) in candidates {
                if settings[study_start..]
                    .iter()
                    .any(|s: &Setting| s.name == name)
                {
                    return Err(
                        self.invalid(field, format!("the setting '{name}' is listed twice"))
                    );
                }
                let mut setting = Setting {
                    study: i,
                    name,
                    overrides,
                    is_reference,
                    field: field.clone(),
                    duration_s: 0.0,
                    window: None,
                    start_x_m: Vec::new(),
                };
                let scene = self
                    .scene(&setting)
                    .map_err(|e| self.invalid(field.clone(), e.to_string()))?;
                match study.quantity {
                    Quantity::RobotSpeed => {
                        let robot = scene.config.robot.as_ref().ok_or_else(|| {
                            self.invalid(
                                at("base_scene"),
                                "robot_speed needs a scene with a `robot`",
                            )
                        })?;
                        let window = GaitWindow::after_settling(
                            study.settle_s,
                            study.cycles,
                            robot.gait.frequency_hz,
                        );
                        setting.duration_s = window.until_s;
                        setting.window = Some(window);
                        setting.start_x_m = start_positions_m(
                            robot.initial_pose.position_m[0],
                            study.starts,
                            study.start_spacing_m,
                        );
                    }
                    Quantity::CollapseRunout => {
                        if scene.config.column_collapse.is_none() || scene.sand().is_none() {
                            return Err(self.invalid(
                                at("base_scene"),
                                "collapse_runout needs a scene with `sand` and `column_collapse`",
                            ));
                        }
                        setting.duration_s = scene.config.duration_s;
                    }
                }
                settings.push(setting);
            }
        }
        Ok(settings)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str) -> Result<Sweep, SweepError> {
        Sweep::from_yaml(text, Path::new("sweep.yaml"))
    }

    fn error_of(text: &str) -> String {
        load(text).expect_err("an invalid sweep").to_string()
    }

    /// A robot study on the whole bed: the shipped sand window's 5 cm step is no whole number of
    /// the 7.5 mm cells of the references below.
    const ROBOT_STUDY: &str = "name: s\nstudies:\n  - name: robot\n    base_scene: config/robot_on_sand.yaml\n    overrides: [sand.window=null]\n    quantity: robot_speed\n";

    #[test]
    fn shipped_track_and_fine_sweeps_load_with_their_starts() {
        let starts = |file: &str| {
            let sweep = Sweep::load(Path::new(file)).unwrap();
            assert_eq!(
                sweep
                    .settings
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>(),
                ["reference", "baseline", "window_only"],
                "{file}"
            );
            sweep.settings[0].start_x_m.clone()
        };
        let fine = Sweep::load(Path::new("config/sweeps/robot_fine.yaml")).unwrap();
        assert_eq!(fine.settings.len(), 2);
        assert_eq!(fine.settings[0].start_x_m, [0.0, 0.002, 0.004]);
        let mut all = starts("config/sweeps/track.yaml");
        all.extend(starts("config/sweeps/track_more_starts.yaml"));
        let expected = [0.0, 0.002, 0.004, 0.0003, 0.001, 0.0017, 0.0024];
        assert_eq!(all.len(), expected.len());
        for (x, e) in all.iter().zip(expected) {
            assert!((x - e).abs() < 1e-9, "{all:?}");
        }
    }

    #[test]
    fn shipped_accuracy_sweep_lists_reference_baseline_axes_and_named_settings() {
        let sweep = Sweep::load(Path::new("config/sweeps/accuracy.yaml")).unwrap();
        let names = |study: usize| -> Vec<&str> {
            sweep
                .settings
                .iter()
                .filter(|s| s.study == study)
                .map(|s| s.name.as_str())
                .collect()
        };
        let robot = names(0);
        assert_eq!(robot[..3], ["reference", "baseline", "dx_m=0.02"]);
        assert!(
            robot.contains(&"E_pa=500000.0")
                && robot.contains(&"model=rft")
                && robot.contains(&"particles_per_cell=1"),
            "{robot:?}"
        );
        assert_eq!(robot[robot.len() - 2..], ["coarse_dx2cm_ppc1", "sleep"]);
        // Three starts 2 mm apart, from the scene's x = 0.
        assert_eq!(sweep.settings[0].start_x_m, [0.0, 0.002, 0.004]);
        assert!(sweep.settings[0].is_reference);
        // 2 Hz, settle 0.5 s, 2 cycles: measured from 0.375 s, run to 1.625 s.
        let window = sweep.settings[0].window.unwrap();
        assert!((window.from_s - 0.375).abs() < 1e-12 && (window.until_s - 1.625).abs() < 1e-12);
        assert_eq!(sweep.settings[0].duration_s, window.until_s);
        assert_eq!(names(1), ["reference", "baseline", "shallow_3cm", "wider"]);
        let collapse = names(2);
        assert_eq!(
            collapse[0], "baseline",
            "the law is the collapse's reference"
        );
        assert_eq!(collapse.len(), 12);
        assert_eq!(collapse[10..], ["E_1e5_baseline_dt", "E_1e5_cfl0.2_dt"]);
        let only = sweep.only_studies(&["collapse".into()]).unwrap();
        assert!(only.settings.iter().all(|s| s.study == 2));
    }

    #[test]
    fn shipped_collapse_law_and_robot_stiffness_sweeps_load() {
        let law = Sweep::load(Path::new("config/sweeps/collapse_law.yaml")).unwrap();
        // The baseline (a = 1 at 3 mm) and eleven named settings, a = 0.5 to 8 at 3 and 2 mm.
        assert_eq!(law.settings.len(), 12);
        assert_eq!(law.settings[0].name, "baseline");
        assert_eq!(law.settings[11].name, "a8_2mm");
        let stiffness = Sweep::load(Path::new("config/sweeps/robot_stiffness.yaml")).unwrap();
        // Per transfer: the stiff reference and the soft baseline, with AFLIP also the soft
        // sand at the stiff sand's step; CFL 0.2 (reference), 0.4 (baseline) and 0.8 with
        // AFLIP; soft sand at its own and at the stiff step with the CPIC band as the bulk,
        // undamped and damped; the defaults at CFL 0.2 (reference), 0.4 and 0.8 and at E 0.5
        // and 5 MPa; five starts each with AFLIP, three with APIC (study 1).
        assert_eq!(stiffness.settings.len(), 17);
        assert!(stiffness
            .settings
            .iter()
            .any(|s| s.name == "soft_at_the_stiff_step"));
        assert!(stiffness
            .settings
            .iter()
            .all(|s| s.start_x_m.len() == if s.study == 1 { 3 } else { 5 }));
    }

    #[test]
    fn errors_name_the_field() {
        let robot = error_of(ROBOT_STUDY);
        assert!(
            robot.contains("studies.0.reference") && robot.contains("robot_speed"),
            "{robot}"
        );
        let bad_key = error_of(&format!(
            "{ROBOT_STUDY}    reference: [sand.dx_m=0.0075]\n    vary:\n      - key: sand.dx\n        values: [0.02]\n"
        ));
        assert!(
            bad_key.contains("studies.0.vary.0.values.0") && bad_key.contains("sand.dx"),
            "{bad_key}"
        );
        let twice = error_of(&format!(
            "{ROBOT_STUDY}    reference: [sand.dx_m=0.0075]\n    vary:\n      - key: sand.dx_m\n        values: [0.02, 0.02]\n"
        ));
        assert!(
            twice.contains("studies.0.vary.0.values.1") && twice.contains("twice"),
            "{twice}"
        );
        let collapse = error_of(
            "name: s\nstudies:\n  - name: c\n    base_scene: config/robot_on_sand.yaml\n    quantity: collapse_runout\n",
        );
        assert!(
            collapse.contains("studies.0.base_scene") && collapse.contains("column_collapse"),
            "{collapse}"
        );
        let unknown = error_of("name: s\nstudies: []\nextra: 1\n");
        assert!(unknown.contains("extra"), "{unknown}");
        let empty = error_of("name: s\nstudies: []\n");
        assert!(
            empty.contains("studies") && empty.contains("at least one"),
            "{empty}"
        );
        let missing = Sweep::load(Path::new("config/sweeps/none.yaml"))
            .unwrap_err()
            .to_string();
        assert!(missing.contains("config/sweeps/none.yaml"), "{missing}");
    }
}
