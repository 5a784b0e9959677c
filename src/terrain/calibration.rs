//! `sandstep calibrate-rft`: the medium scale zeta of resistive force theory measured on MPM
//! sand. A square horizontal plate (a CPIC sheet) is pressed at constant speed into a settled
//! bed of the sand ([`super::plate`]); the upward force, averaged over each grid cell of depth
//! (the CPIC force saws with the grid period), is fitted by least squares through the origin as
//! `F = zeta A depth` (Li, Zhang and Goldman 2013: `alpha_z(0, 90 deg) = zeta`). Settings:
//! `terrain.rft.calibration` ([`RftCalibrationConfig`]; `docs/physics.md`, "Calibration"). The
//! bed is built from a scene by `Scene::rft_calibration_bed`.

use std::time::Instant;

use serde::Serialize;

use super::config::RftCalibrationConfig;
use super::plate::{depth_cell_means, fit_line, press_plate, PlatePress, PlateSample};
use crate::mpm::{SimError, Solver};

/// What `calibrate-rft` measured (`--json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct RftCalibration {
    /// Scene file.
    pub scene: String,
    /// The sand material pressed.
    pub material: String,
    /// Fitted medium scale (N/m^3): `F = zeta A depth`, least squares through the origin.
    pub zeta_n_m3: f64,
    /// Fit quality: `1 - SS_res / SS_tot` of the cell means (SS_tot about their mean).
    pub r_squared: f64,
    /// Plate side (m) and area (m^2).
    pub plate_side_m: f64,
    pub plate_area_m2: f64,
    /// Depth of the plate's mid-plane at the end (m).
    pub final_depth_m: f64,
    /// Pressing speed (m/s).
    pub speed_m_s: f64,
    /// Grid spacing (m), bed side and depth (m).
    pub dx_m: f64,
    pub bed_side_m: f64,
    pub bed_depth_m: f64,
    pub particles: usize,
    /// Mean MPM force over the deepest cell of depth (N), at that cell's mid-depth (m), and the
    /// fitted RFT force there (N).
    pub last_cell_depth_m: f64,
    pub last_cell_force_n: f64,
    pub last_cell_rft_force_n: f64,
    /// Mean force per cell of depth (the fitted points).
    pub cells: Vec<PlateSample>,
    /// Wall time of the MPM run (s).
    pub wall_time_s: f64,
}

/// Settles `solver` (the calibration's bed of sand, `c.bed_side_m` square and `c.bed_depth_m`
/// deep, from the origin), runs the plate test of `c` on it with sand-plate friction
/// `friction` and fits zeta. `scene` and `material` name what was calibrated.
pub fn calibrate(
    solver: &mut Solver,
    c: &RftCalibrationConfig,
    friction: f32,
    scene: String,
    material: String,
) -> Result<RftCalibration, SimError> {
    let wall = Instant::now();
    solver.advance_to(c.settle_s)?;
    let press = PlatePress {
        start_m: [0.5 * c.bed_side_m, 0.5 * c.bed_side_m, c.bed_depth_m],
        half_extents_m: [
            0.5 * c.plate_side_m,
            0.5 * c.plate_side_m,
            0.5 * c.plate_thickness_m,
        ],
        speed_m_s: c.speed_m_s,
        final_depth_m: c.final_depth_m,
        window_s: c.window_s,
        friction,
    };
    let samples = press_plate(solver, &press)?;
    let wall_time_s = wall.elapsed().as_secs_f64();
    let cells = depth_cell_means(&samples, c.dx_m as f64, c.final_depth_m as f64);
    let area = (c.plate_side_m as f64).powi(2);
    let points: Vec<(f64, f64)> = cells.iter().map(|s| (s.depth_m, s.force_n)).collect();
    let fit = fit_line(&points, true);
    let zeta_n_m3 = fit.slope / area;
    let last = cells.last().copied().unwrap_or(PlateSample {
        depth_m: f64::NAN,
        force_n: f64::NAN,
    });
    Ok(RftCalibration {
        scene,
        material,
        zeta_n_m3,
        r_squared: fit.r_squared,
        plate_side_m: c.plate_side_m as f64,
        plate_area_m2: area,
        final_depth_m: c.final_depth_m as f64,
        speed_m_s: c.speed_m_s as f64,
        dx_m: c.dx_m as f64,
        bed_side_m: c.bed_side_m as f64,
        bed_depth_m: c.bed_depth_m as f64,
        particles: solver.particles.len(),
        last_cell_depth_m: last.depth_m,
        last_cell_force_n: last.force_n,
        last_cell_rft_force_n: zeta_n_m3 * area * last.depth_m,
        cells,
        wall_time_s,
    })
}
