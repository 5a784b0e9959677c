//! The `terrain:` section of a scene: what the robot walks on. `model: mpm` (the default) is
//! the MPM sand of the `sand` section, coupled by CPIC; `model: rft` is resistive force theory
//! ([`super::rft`], `docs/physics.md`), a flat granular surface whose resistance is computed
//! per surface element, 3 to 16 times faster than real time. With `rft` the `sand` section is
//! not simulated (it stays loadable, so one file switches with `--set terrain.model=rft`, and
//! `sandstep calibrate-rft` reads its material), and the rigid floor `robot.ground.height_m`
//! stays the bed's bottom.

use std::path::PathBuf;

use serde::Deserialize;

use super::stress_law::StressLaw;
use super::stress_map::{StressMapFile, StressProbe};
use crate::config_error::FieldError;

/// Default medium scale zeta (N/m^3): `sandstep calibrate-rft config/robot_on_sand.yaml`,
/// the MPM plate test on that scene's sand (friction angle 45 deg, dx 5 mm: 4.46e7, R^2 0.96;
/// `docs/physics.md`, "Resistive force theory"). Li et al.'s loosely packed poppy seeds are
/// about [`POPPY_SEEDS_ZETA_N_M3`].
pub const DEFAULT_ZETA_N_M3: f64 = 4.46e7;

/// Zeta of loosely packed poppy seeds (N/m^3): 0.25-0.35 N/cm^3 (Li, Zhang and Goldman 2013),
/// the medium of the published RFT robot predictions.
pub const POPPY_SEEDS_ZETA_N_M3: f64 = 3.0e5;

/// `terrain:`.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TerrainConfig {
    /// `mpm` or `rft`. Default `mpm`.
    #[serde(default)]
    pub model: TerrainModel,
    /// Resistive force theory settings (used with `model: rft` and by `calibrate-rft`).
    #[serde(default)]
    pub rft: RftConfig,
}

/// `terrain.model`.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum TerrainModel {
    /// The MPM sand of the `sand` section, coupled by CPIC.
    #[default]
    Mpm,
    /// Resistive force theory on a flat surface.
    Rft,
}

/// `terrain.rft`.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RftConfig {
    /// Medium scale zeta: vertical stress per unit depth under a horizontal plate pressed
    /// straight down (N/m^3), > 0, of Li et al.'s generic shape. Default
    /// [`DEFAULT_ZETA_N_M3`], calibrated on the default sand. Not used with `stress_maps`.
    pub zeta_n_m3: f64,
    /// The stress law from stress maps measured on the MPM sand instead of the generic shape
    /// ([`StressMapsChoice`]). Default none.
    pub stress_maps: Option<StressMapsChoice>,
    /// Height of the flat sand surface (m), at or above `robot.ground.height_m`. Default 0
    /// (the robot starts just above z = 0 in every scene).
    pub surface_height_m: f64,
    /// Longest edge of a surface element (m), > 0; boxes thinner than this are thin plates
    /// (the legs). Default 0.005.
    pub element_size_m: f64,
    /// Regularisation speed v_ref (m/s), > 0: an element slower than this feels the fraction
    /// |v| / v_ref of its RFT force. Default 0.01.
    pub reference_speed_m_s: f64,
    /// The rapier step with RFT forces: `auto` (the default: [`RftStep::seconds`] on the
    /// generic shape, [`RFT_AUTO_MAPS_DT_S`] with stress maps) or a number of seconds in
    /// (0, 0.01]. The forces and their implicit terms are computed once
    /// per step; `robot.physics.max_dt_s` does not apply.
    pub max_dt_s: RftStep,
    /// The MPM plate test of `sandstep calibrate-rft`.
    pub calibration: RftCalibrationConfig,
}

impl Default for RftConfig {
    fn default() -> Self {
        RftConfig {
            zeta_n_m3: DEFAULT_ZETA_N_M3,
            stress_maps: None,
            surface_height_m: 0.0,
            element_size_m: 0.005,
            reference_speed_m_s: 0.01,
            max_dt_s: RftStep::Auto(AutoKeyword::Auto),
            calibration: RftCalibrationConfig::default(),
        }
    }
}

/// Largest RFT step of `auto` (s): at 2 Hz the hexapod walks within 1 % of its 0.25 ms speed
/// with 8 ms steps on poppy seeds and 10 % slower with 10 ms (the legs turn 0.13 rad a step).
pub const RFT_AUTO_MAX_DT_S: f64 = 0.008;

/// `auto` step times the square root of zeta (s (N/m^3)^(1/2)): the period of the terrain's
/// stiffness `zeta A` against the robot's inertia scales as `1/sqrt(zeta)`. Measured on the
/// hexapod at 2 Hz (speed over 4 s within 2 % of 0.25 ms steps): 4 ms at zeta = 3e6, 1 ms at
/// 4.46e7 (3.5 %; 2 ms is 12 % off). docs/physics.md, "Resistive force theory".
pub const RFT_AUTO_STEP_SQRT_ZETA: f64 = 6.9;

/// The `auto` step with stress maps (s). Their laws are not the generic shape scaled, so
/// [`RFT_AUTO_STEP_SQRT_ZETA`] does not carry over: on the shipped sand's table (zeta 3.1e6,
/// which that rule would step at 3.9 ms), 3.3 ms steps walked the C-legs 9 % slower than
/// 0.25 ms steps at 4 Hz; 1 ms steps were within 2 % for C-legs and 4 % for reversed legs at
/// 1, 2 and 4 Hz (the fitted form: within 1.5 % for C-legs at 1 and 2 Hz, 11 % at 4 Hz,
/// where its walk is sensitive to the step). docs/physics.md, "Stress maps".
pub const RFT_AUTO_MAPS_DT_S: f64 = 0.001;

/// Largest accepted RFT step (s), as for rapier's steps on rigid ground.
pub const RFT_MAX_DT_S: f64 = 0.01;

/// `terrain.rft.max_dt_s`: `auto` or seconds.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(untagged, expecting = "a step in seconds or `auto`")]
pub enum RftStep {
    Auto(AutoKeyword),
    Seconds(f64),
}

/// The word `auto`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AutoKeyword {
    Auto,
}

impl RftStep {
    /// The step (s) on a medium of scale `zeta_n_m3`: `auto` is
    /// `min(RFT_AUTO_MAX_DT_S, RFT_AUTO_STEP_SQRT_ZETA / sqrt(zeta))`, 1.03 ms on the default
    /// zeta and 8 ms on poppy seeds.
    pub fn seconds(self, zeta_n_m3: f64) -> f64 {
        match self {
            RftStep::Seconds(s) => s,
            RftStep::Auto(_) => (RFT_AUTO_STEP_SQRT_ZETA / zeta_n_m3.sqrt()).min(RFT_AUTO_MAX_DT_S),
        }
    }
}

/// `terrain.rft.stress_maps`: RFT's stress law from a stress-map file, written by `sandstep
/// calibrate-rft <scene> --maps --write FILE` ([`StressMapFile`]).
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StressMapsChoice {
    /// The file (YAML), relative to the working directory, e.g.
    /// `config/stress_maps/sand_dx10mm.yaml`. Required.
    pub file: PathBuf,
    /// Which law: `table` (the measured points, interpolated bilinearly; the default) or
    /// `fit` (the generic Fourier form fitted to them).
    #[serde(default)]
    pub law: MapsLaw,
    /// The file as read when the scene was loaded ([`RftConfig::read_stress_maps`]).
    #[serde(skip)]
    pub read: Option<Box<StressMapFile>>,
}

/// `terrain.rft.stress_maps.law`.
#[derive(Clone, Copy, Debug, Default, Deserialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum MapsLaw {
    /// The measured points, bilinear in beta and gamma.
    #[default]
    Table,
    /// The nine-coefficient Fourier form fitted to the points.
    Fit,
}

impl RftConfig {
    /// Reads the `stress_maps` file, if any, into the configuration; errors name the field
    /// and the problem (missing file, malformed YAML, a table that cannot be used).
    pub fn read_stress_maps(&mut self) -> Result<(), FieldError> {
        let Some(choice) = &mut self.stress_maps else {
            return Ok(());
        };
        let field = "terrain.rft.stress_maps.file";
        let problem = |message: String| {
            FieldError::new(field, format!("{}: {message}", choice.file.display()))
        };
        let text = std::fs::read_to_string(&choice.file).map_err(|e| {
            problem(format!(
                "{e} (`sandstep calibrate-rft <scene> --maps --write FILE` writes one)"
            ))
        })?;
        let file: StressMapFile = serde_yaml_ng::from_str(&text)
            .map_err(|e| problem(format!("not a stress-map file: {e}")))?;
        file.table
            .check()
            .map_err(|e| problem(format!("table.{e}")))?;
        file.coefficients
            .check()
            .map_err(|e| problem(format!("coefficients.{e}")))?;
        choice.read = Some(Box::new(file));
        Ok(())
    }

    /// The stress law: the generic shape scaled by `zeta_n_m3`, or the stress maps' as read
    /// by [`Self::read_stress_maps`], which every scene load does ([`crate::scene::Scene`]).
    /// A configuration built otherwise, its maps not read, has the generic shape's law and
    /// step alike.
    pub fn law(&self) -> StressLaw {
        match self.read_maps() {
            Some((MapsLaw::Table, file)) => StressLaw::Table(file.table.clone()),
            Some((MapsLaw::Fit, file)) => StressLaw::fitted(&file.coefficients),
            None => StressLaw::generic(self.zeta_n_m3),
        }
    }

    /// The rapier step with RFT forces (s), `max_dt_s` resolved: `auto` is
    /// [`RftStep::seconds`] on the generic shape's zeta, [`RFT_AUTO_MAPS_DT_S`] with stress
    /// maps.
    pub fn step_s(&self) -> f64 {
        match (self.max_dt_s, self.read_maps()) {
            (RftStep::Auto(_), Some(_)) => RFT_AUTO_MAPS_DT_S,
            (step, _) => step.seconds(self.zeta_n_m3),
        }
    }

    /// The stress-map file as read ([`Self::read_stress_maps`]), with its law.
    fn read_maps(&self) -> Option<(MapsLaw, &StressMapFile)> {
        let choice = self.stress_maps.as_ref()?;
        Some((choice.law, choice.read.as_deref()?))
    }

    /// The parameters of the RFT terrain model.
    pub fn params(&self) -> RftParams {
        RftParams {
            law: self.law(),
            surface_height_m: self.surface_height_m,
            element_size_m: self.element_size_m,
            reference_speed_m_s: self.reference_speed_m_s,
        }
    }
}

/// `terrain.rft.calibration`: a square horizontal plate pressed at constant speed into a
/// settled square bed of the scene's sand (MPM, CPIC), in a box with slip walls reaching one
/// plate side above the surface.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RftCalibrationConfig {
    /// Sand material, a name under `sand.materials`. Default: the first sand body's.
    pub material: Option<String>,
    /// Grid spacing of the test (m), > 0. Default 0.005.
    pub dx_m: f32,
    /// Side of the square plate (m), > 0. Default 0.02.
    pub plate_side_m: f32,
    /// Plate thickness (m), > 0 and below `dx_m` (a CPIC sheet). Default 0.001.
    pub plate_thickness_m: f32,
    /// Side of the square bed (m), > `plate_side_m`. Default 0.08.
    pub bed_side_m: f32,
    /// Depth of the bed (m), > `final_depth_m`. Default 0.05.
    pub bed_depth_m: f32,
    /// Pressing speed (m/s), > 0. Default 0.1.
    pub speed_m_s: f32,
    /// Depth of the plate's mid-plane at the end (m), at least 2 `dx_m`. Default 0.02.
    pub final_depth_m: f32,
    /// Settling time of the bed under gravity before pressing (s), >= 0. Default 0.05.
    pub settle_s: f64,
    /// The force is averaged over windows of this length (s), > 0. Default 0.001.
    pub window_s: f64,
    /// The stress maps of `sandstep calibrate-rft --maps`.
    pub maps: StressMapConfig,
}

/// `terrain.rft.calibration.maps`: a leg-sized plate moved through a settled bed of the
/// scene's sand at each attack angle beta and intrusion angle gamma
/// ([`super::stress_map`]), the stress per unit depth measured and fitted with RFT's generic
/// form. Each point is a fresh bed, settled for `settle_s` of the calibration.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StressMapConfig {
    /// Grid spacing (m), > 0. Default: the scene's `sand.dx_m` (the grid the robot walks on).
    pub dx_m: Option<f32>,
    /// The bed: length along the motion (x), width (y) and depth (m). Default 0.16, 0.06,
    /// 0.09.
    pub bed_m: [f32; 3],
    /// Attack angles beta of the fitted points (deg). Default -60 to 90 by 30.
    pub betas_deg: Vec<f64>,
    /// Intrusion angles gamma of the fitted points (deg), in [-90, 90]. Default -90 to 90
    /// by 30.
    pub gammas_deg: Vec<f64>,
    /// Points not fitted, on which the fit is checked: `[beta, gamma]` (deg). Default
    /// `[45, 15]`, `[-15, 45]`, `[75, -45]`.
    pub check_deg: Vec<[f64; 2]>,
    /// The plate and its motion ([`StressProbe`]: a 4.1 x 1 cm leg, 3 mm thick, at 0.1 m/s,
    /// moved 3 cm and fitted over the last 2, its top at least 5 mm deep).
    pub probe: StressProbe,
}

impl Default for StressMapConfig {
    fn default() -> Self {
        StressMapConfig {
            dx_m: None,
            bed_m: [0.16, 0.06, 0.09],
            betas_deg: vec![-60.0, -30.0, 0.0, 30.0, 60.0, 90.0],
            gammas_deg: vec![-90.0, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0],
            check_deg: vec![[45.0, 15.0], [-15.0, 45.0], [75.0, -45.0]],
            probe: StressProbe::default(),
        }
    }
}

impl Default for RftCalibrationConfig {
    fn default() -> Self {
        RftCalibrationConfig {
            material: None,
            dx_m: 0.005,
            plate_side_m: 0.02,
            plate_thickness_m: 0.001,
            bed_side_m: 0.08,
            bed_depth_m: 0.05,
            speed_m_s: 0.1,
            final_depth_m: 0.02,
            settle_s: 0.05,
            window_s: 0.001,
            maps: StressMapConfig::default(),
        }
    }
}

impl TerrainConfig {
    /// Checks the section; errors name the field. `robot_floor_m` is the scene's
    /// `robot.ground.height_m` (None without a robot), `materials` the names under
    /// `sand.materials` (None without sand).
    pub fn validate(
        &self,
        robot_floor_m: Option<f64>,
        materials: Option<&[&str]>,
    ) -> Result<(), FieldError> {
        validate(self, robot_floor_m)?;
        validate_calibration(&self.rft.calibration, materials)
    }
}

/// `v` as the value of `field`: an error unless it is a finite number > 0.
fn positive_field(field: String, v: f64) -> Result<(), FieldError> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(FieldError::new(
            field,
            format!("{v} must be a finite number > 0"),
        ))
    }
}

// Negated comparisons (`!(a > b)`) on purpose: they reject NaN too.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn validate(t: &TerrainConfig, robot_floor_m: Option<f64>) -> Result<(), FieldError> {
    let rft = &t.rft;
    let field = |f: &str| format!("terrain.rft.{f}");
    let positive = |f: &str, v: f64| positive_field(field(f), v);
    positive("zeta_n_m3", rft.zeta_n_m3)?;
    positive("element_size_m", rft.element_size_m)?;
    positive("reference_speed_m_s", rft.reference_speed_m_s)?;
    if let RftStep::Seconds(step) = rft.max_dt_s {
        positive("max_dt_s", step)?;
        if step > RFT_MAX_DT_S {
            return Err(FieldError::new(
                field("max_dt_s"),
                format!("{step} s must be at most {RFT_MAX_DT_S} s"),
            ));
        }
    }
    if !rft.surface_height_m.is_finite() {
        return Err(FieldError::new(field("surface_height_m"), "must be finite"));
    }
    if let Some(floor) = robot_floor_m {
        if !(rft.surface_height_m >= floor) {
            return Err(FieldError::new(
                field("surface_height_m"),
                format!(
                    "{} m is below the rigid floor robot.ground.height_m = {floor} m",
                    rft.surface_height_m
                ),
            ));
        }
    }
    if t.model == TerrainModel::Rft && robot_floor_m.is_none() {
        return Err(FieldError::new(
            "terrain.model",
            "`rft` needs a `robot` section (the bodies the terrain acts on)",
        ));
    }
    Ok(())
}

#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn validate_calibration(
    c: &RftCalibrationConfig,
    materials: Option<&[&str]>,
) -> Result<(), FieldError> {
    let field = |f: &str| format!("terrain.rft.calibration.{f}");
    let check = |f: &str, ok: bool, v: f64, rule: &str| {
        if ok {
            Ok(())
        } else {
            Err(FieldError::new(field(f), format!("{v} must be {rule}")))
        }
    };
    let positive = |v: f64| v > 0.0 && v.is_finite();
    for (f, v) in [
        ("dx_m", c.dx_m),
        ("plate_side_m", c.plate_side_m),
        ("plate_thickness_m", c.plate_thickness_m),
        ("bed_side_m", c.bed_side_m),
        ("bed_depth_m", c.bed_depth_m),
        ("speed_m_s", c.speed_m_s),
        ("final_depth_m", c.final_depth_m),
    ] {
        check(f, positive(v as f64), v as f64, "a finite number > 0")?;
    }
    check(
        "window_s",
        positive(c.window_s),
        c.window_s,
        "a finite number > 0",
    )?;
    check(
        "settle_s",
        c.settle_s >= 0.0 && c.settle_s.is_finite(),
        c.settle_s,
        "a finite number >= 0",
    )?;
    check(
        "plate_thickness_m",
        c.plate_thickness_m < c.dx_m,
        c.plate_thickness_m as f64,
        &format!("below dx_m = {} (the plate is a CPIC sheet)", c.dx_m),
    )?;
    check(
        "bed_side_m",
        c.bed_side_m > c.plate_side_m,
        c.bed_side_m as f64,
        &format!("larger than plate_side_m = {}", c.plate_side_m),
    )?;
    check(
        "final_depth_m",
        c.final_depth_m >= 2.0 * c.dx_m,
        c.final_depth_m as f64,
        &format!(
            "at least 2 dx_m = {} (one force mean per cell)",
            2.0 * c.dx_m
        ),
    )?;
    check(
        "bed_depth_m",
        c.bed_depth_m > c.final_depth_m,
        c.bed_depth_m as f64,
        &format!("deeper than final_depth_m = {}", c.final_depth_m),
    )?;
    validate_maps(&c.maps)?;
    if let (Some(name), Some(known)) = (&c.material, materials) {
        if !known.contains(&name.as_str()) {
            return Err(FieldError::new(
                field("material"),
                format!("unknown material `{name}` (materials: {known:?})"),
            ));
        }
    }
    Ok(())
}

/// Largest attack or intrusion angle of the stress maps (deg): Li et al.'s range, which RFT's
/// symmetries extend to every angle.
pub const MAX_MAP_ANGLE_DEG: f64 = 90.0;

/// Checks `terrain.rft.calibration.maps`; errors name the field.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
fn validate_maps(m: &StressMapConfig) -> Result<(), FieldError> {
    let field = |f: &str| format!("terrain.rft.calibration.maps.{f}");
    let positive = |f: &str, v: f64| positive_field(field(f), v);
    if let Some(dx) = m.dx_m {
        positive("dx_m", dx as f64)?;
    }
    for (i, side) in m.bed_m.iter().enumerate() {
        positive(&format!("bed_m.{i}"), *side as f64)?;
    }
    let p = &m.probe;
    for (f, v) in [
        ("probe.chord_m", p.chord_m as f64),
        ("probe.width_m", p.width_m as f64),
        ("probe.thickness_m", p.thickness_m as f64),
        ("probe.speed_m_s", p.speed_m_s as f64),
        ("probe.travel_m", p.travel_m as f64),
        ("probe.window_s", p.window_s),
    ] {
        positive(f, v)?;
    }
    if !(p.build_up_m >= 0.0 && p.build_up_m < p.travel_m) {
        return Err(FieldError::new(
            field("probe.build_up_m"),
            format!(
                "{} must be >= 0 and below travel_m = {}",
                p.build_up_m, p.travel_m
            ),
        ));
    }
    positive("probe.min_depth_m", p.min_depth_m as f64)?;
    if !(p.thickness_m < p.width_m.min(p.chord_m)) {
        return Err(FieldError::new(
            field("probe.thickness_m"),
            format!(
                "{} must be below width_m and chord_m (the plate's thin side)",
                p.thickness_m
            ),
        ));
    }
    let angle = |f: String, v: f64| {
        if v.abs() <= MAX_MAP_ANGLE_DEG {
            Ok(())
        } else {
            let message = format!("{v} deg must be within +-{MAX_MAP_ANGLE_DEG} deg");
            Err(FieldError::new(f, message))
        }
    };
    for (i, &b) in m.betas_deg.iter().enumerate() {
        angle(field(&format!("betas_deg.{i}")), b)?;
    }
    for (i, &g) in m.gammas_deg.iter().enumerate() {
        angle(field(&format!("gammas_deg.{i}")), g)?;
    }
    for (i, [b, g]) in m.check_deg.iter().enumerate() {
        angle(field(&format!("check_deg.{i}.0")), *b)?;
        angle(field(&format!("check_deg.{i}.1")), *g)?;
    }
    Ok(())
}

/// The RFT medium and how bodies are discretised.
#[derive(Clone, Debug, PartialEq)]
pub struct RftParams {
    /// The medium's stress law ([`super::stress_law`]).
    pub law: StressLaw,
    /// Height of the flat free surface (m): depth is measured from it.
    pub surface_height_m: f64,
    /// Longest edge of a surface element (m), > 0; also the thickness below which a box is a
    /// thin plate.
    pub element_size_m: f64,
    /// Regularisation speed v_ref (m/s), > 0: an element slower than this feels the fraction
    /// `|v| / v_ref` of its RFT force.
    pub reference_speed_m_s: f64,
}
