//! `sandstep drag-blade`: a vertical blade (a CPIC sheet) dragged sideways at constant speed
//! through a settled bed of the scene's sand, the bed of `sandstep calibrate-rft`
//! ([`super::calibration`]). One-way and kinematic, so its run is deterministic and has no
//! exchange, motors or robot in it: the probe of `docs/speed-vs-accuracy.md` ("A blade dragged
//! through the sand") for how the sand's resistance to a moving body follows the step.

use serde::Serialize;

use super::config::RftCalibrationConfig;
use super::plate::{move_plate, PlateMotion, PlateSample};
use crate::mpm::{SimError, Solver};

/// The blade and its motion. The bed is `[0, side]^2 x [0, depth]` (m) with its surface at
/// `z = depth`; the blade moves along +x.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BladeDrag {
    /// Width across the motion, along y (m).
    pub width_m: f32,
    /// Height (m).
    pub height_m: f32,
    /// How far its top stands above the sand surface (m); negative: buried.
    pub top_above_surface_m: f32,
    /// Speed along +x (m/s).
    pub speed_m_s: f32,
    /// Distance dragged (m).
    pub travel_m: f32,
    /// Its centre at the start, from the bed's centre along x and y (m).
    pub start_offset_m: [f32; 2],
    /// The force is averaged over windows of this much simulated time (s).
    pub window_s: f64,
    /// Thickness (m), below the grid spacing: a CPIC sheet.
    pub thickness_m: f32,
}

/// What `drag-blade` measured (`--json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct BladeDragResult {
    pub scene: String,
    pub material: String,
    pub blade: BladeDrag,
    /// Grid spacing, bed side and depth (m).
    pub dx_m: f64,
    pub bed_side_m: f64,
    pub bed_depth_m: f64,
    pub particles: usize,
    /// Substeps taken while the blade moved.
    pub substeps: u64,
    /// Mean force against the motion over the first and the second half of the windows, about
    /// the first and the second half of the travel (N).
    pub first_half_force_n: f64,
    pub second_half_force_n: f64,
    /// Per window: distance travelled (m) and mean force against the motion (N).
    pub samples: Vec<PlateSample>,
    /// Wall time of the MPM run (s).
    pub wall_time_s: f64,
}

/// The blade must lie within the bed, below the bed's headroom, and move; names the option.
pub fn check(blade: &BladeDrag, c: &RftCalibrationConfig) -> Result<(), String> {
    let positive = [
        ("--width", blade.width_m),
        ("--height", blade.height_m),
        ("--speed", blade.speed_m_s),
        ("--travel", blade.travel_m),
    ];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(format!("{name} = {value} must be positive"));
        }
    }
    if !(blade.window_s.is_finite() && blade.window_s > 0.0) {
        return Err(format!("--window = {} must be positive", blade.window_s));
    }
    let half_side = 0.5 * c.bed_side_m;
    let [x, y] = blade.start_offset_m;
    let room = half_side - c.dx_m;
    if x < -room || x + blade.travel_m > room {
        return Err(format!(
            "--start-x = {x} m with --travel = {} m leaves the bed (half side {half_side} m, \
             less a cell)",
            blade.travel_m
        ));
    }
    if y.abs() + 0.5 * blade.width_m > room {
        return Err(format!(
            "--start-y = {y} m with --width = {} m leaves the bed (half side {half_side} m, \
             less a cell)",
            blade.width_m
        ));
    }
    let bottom_depth = blade.height_m - blade.top_above_surface_m;
    if bottom_depth >= c.bed_depth_m - c.dx_m || blade.top_above_surface_m >= c.plate_side_m {
        return Err(format!(
            "--height = {} m with --top-above-surface = {} m: the blade must end above the \
             bed's floor less a cell ({} m deep) and its top below the bed's headroom ({} m)",
            blade.height_m, blade.top_above_surface_m, c.bed_depth_m, c.plate_side_m
        ));
    }
    Ok(())
}

/// Settles `solver` (the calibration bed of `c`) and drags `blade` through it with sand-blade
/// friction `friction`.
pub fn drag_blade(
    solver: &mut Solver,
    c: &RftCalibrationConfig,
    blade: &BladeDrag,
    friction: f32,
) -> Result<(Vec<PlateSample>, u64), SimError> {
    solver.advance_to(c.settle_s)?;
    let centre = 0.5 * c.bed_side_m;
    let [x, y] = blade.start_offset_m;
    let motion = PlateMotion {
        start_m: [
            centre + x,
            centre + y,
            c.bed_depth_m + blade.top_above_surface_m - 0.5 * blade.height_m,
        ],
        half_extents_m: [
            0.5 * blade.thickness_m,
            0.5 * blade.width_m,
            0.5 * blade.height_m,
        ],
        velocity_m_s: [blade.speed_m_s, 0.0, 0.0],
        duration_s: (blade.travel_m / blade.speed_m_s) as f64,
        window_s: blade.window_s,
        friction,
    };
    let substeps_before = solver.steps;
    let samples = move_plate(solver, &motion)?;
    Ok((samples, solver.steps - substeps_before))
}

/// Mean force of the first and of the second half of the windows (N); NaN for an empty half.
pub fn half_means(samples: &[PlateSample]) -> (f64, f64) {
    let mean =
        |part: &[PlateSample]| part.iter().map(|s| s.force_n).sum::<f64>() / part.len() as f64;
    let (first, second) = samples.split_at(samples.len() / 2);
    (mean(first), mean(second))
}
