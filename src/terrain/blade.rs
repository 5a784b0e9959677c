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
    /// How far its top stands above the bed's top before settling (m); negative: buried.
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
    /// Scene file the sand came from.
    pub scene: String,
    /// The sand material of the bed.
    pub material: String,
    /// The blade and its motion.
    pub blade: BladeDrag,
    /// Grid spacing (m).
    pub dx_m: f64,
    /// Bed side (m).
    pub bed_side_m: f64,
    /// Bed depth (m): its top before settling, from which `top_above_surface_m` is measured.
    pub bed_depth_m: f64,
    /// Particles in the bed.
    pub particles: usize,
    /// Substeps taken while the blade moved.
    pub substeps: u64,
    /// Mean force against the motion over the first half of the windows, about the first half
    /// of the travel (N).
    pub first_half_force_n: f64,
    /// The same over the second half (N).
    pub second_half_force_n: f64,
    /// Per window: distance travelled (m; the sample's `depth_m`) and mean force against the
    /// motion (N).
    pub samples: Vec<PlateSample>,
    /// Wall time of the MPM run (s).
    pub wall_time_s: f64,
}

/// Most force windows one drag may take: a `--window` so short that the travel would need
/// more is refused (it would fill memory, and below a substep give empty windows).
pub const MAX_WINDOWS: f64 = 1e5;

/// The blade must lie within the bed, below the bed's headroom, be a sheet thinner than a cell,
/// and move over at least two force windows; the message names the option.
pub fn check(blade: &BladeDrag, c: &RftCalibrationConfig) -> Result<(), String> {
    let positive = [
        ("--width", blade.width_m),
        ("--height", blade.height_m),
        ("--speed", blade.speed_m_s),
        ("--travel", blade.travel_m),
        ("--thickness", blade.thickness_m),
    ];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(format!("{name} = {value} must be positive"));
        }
    }
    let [x, y] = blade.start_offset_m;
    let finite = [
        ("--start-x", x),
        ("--start-y", y),
        ("--top-above-surface", blade.top_above_surface_m),
    ];
    for (name, value) in finite {
        if !value.is_finite() {
            return Err(format!("{name} = {value} must be a number"));
        }
    }
    if blade.thickness_m >= c.dx_m || blade.thickness_m >= blade.width_m.min(blade.height_m) {
        return Err(format!(
            "--thickness = {} m must be below the grid spacing ({} m) and the blade's width and \
             height: a CPIC sheet",
            blade.thickness_m, c.dx_m
        ));
    }
    let duration_s = (blade.travel_m / blade.speed_m_s) as f64;
    if !(blade.window_s.is_finite()
        && blade.window_s <= 0.5 * duration_s
        && blade.window_s >= duration_s / MAX_WINDOWS)
    {
        return Err(format!(
            "--window = {} s must lie between {:.3e} s ({MAX_WINDOWS} windows) and half the \
             drag's {duration_s:.4} s (--travel / --speed), for two halves to average",
            blade.window_s,
            duration_s / MAX_WINDOWS
        ));
    }
    let half_side = 0.5 * c.bed_side_m;
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
    let headroom = c.plate_side_m - c.dx_m;
    if bottom_depth >= c.bed_depth_m - c.dx_m || blade.top_above_surface_m >= headroom {
        return Err(format!(
            "--height = {} m with --top-above-surface = {} m: the blade must end a cell above \
             the bed's floor (above {} m deep) and its top a cell below the headroom (below {} \
             m above the bed, terrain.rft.calibration.plate_side_m less a cell)",
            blade.height_m,
            blade.top_above_surface_m,
            c.bed_depth_m - c.dx_m,
            headroom
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
        pitch_rad: 0.0,
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
