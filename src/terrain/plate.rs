//! A horizontal plate pressed into sand at constant speed through CPIC: the intrusion test of
//! `tests/coupling.rs` and the measurement behind `sandstep calibrate-rft` ([`super::calibration`],
//! `docs/physics.md`). The plate is a thin box whose mid-plane is a CPIC sheet, moved
//! kinematically (one-way: the sand feels it, it records what it would feel).

use rapier3d::glamx::Vec3;
use rapier3d::prelude::{Pose, RigidBodyBuilder, RigidBodySet};
use serde::Serialize;

use crate::coupling::{Coupling, CouplingMode, CpicSurface, SandCollider};
use crate::mpm::{SimError, Solver};

/// How the plate is pressed.
#[derive(Clone, Debug, PartialEq)]
pub struct PlatePress {
    /// Centre of the plate's mid-plane at the start (m); its z is the sand surface, depth 0.
    pub start_m: [f32; 3],
    /// Half extents of the plate (m); the z one is its half thickness.
    pub half_extents_m: [f32; 3],
    /// Downward speed (m/s), > 0.
    pub speed_m_s: f32,
    /// Depth of the mid-plane below the start at the end (m).
    pub final_depth_m: f32,
    /// The force is averaged over windows of this much simulated time (s).
    pub window_s: f64,
    /// Coulomb friction coefficient sand-plate (-).
    pub friction: f32,
}

/// The sand's mean force on the plate over one window.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PlateSample {
    /// How far the plate's mid-plane has moved at the end of the window (m): pressed, its
    /// depth below the start.
    pub depth_m: f64,
    /// Force against the motion (N): the impulse over the window along the motion's reverse,
    /// divided by the window's length; pressed, the upward force.
    pub force_n: f64,
}

/// Presses the plate from `press.start_m` down to `press.final_depth_m` at constant speed,
/// stepping `sand` with the CPIC coupling (the step also bounded by
/// [`Coupling::max_dt_s`]), and returns one sample per window.
pub fn press_plate(sand: &mut Solver, press: &PlatePress) -> Result<Vec<PlateSample>, SimError> {
    let motion = PlateMotion {
        start_m: press.start_m,
        half_extents_m: press.half_extents_m,
        velocity_m_s: [0.0, 0.0, -press.speed_m_s],
        duration_s: (press.final_depth_m / press.speed_m_s) as f64,
        window_s: press.window_s,
        friction: press.friction,
        pitch_rad: 0.0,
    };
    move_plate(sand, &motion)
}

/// A thin box (its mid-plane a CPIC sheet, normal to its smallest half extent) moved
/// kinematically at a constant velocity through sand.
#[derive(Clone, Debug, PartialEq)]
pub struct PlateMotion {
    /// Centre at the start (m).
    pub start_m: [f32; 3],
    /// Half extents along x, y, z (m); the smallest is the half thickness.
    pub half_extents_m: [f32; 3],
    /// Velocity (m/s), not zero.
    pub velocity_m_s: [f32; 3],
    /// How long it moves (s).
    pub duration_s: f64,
    /// The force is averaged over windows of this much simulated time (s).
    pub window_s: f64,
    /// Coulomb friction coefficient sand-plate (-).
    pub friction: f32,
    /// The plate turned about +y by this angle (rad, right-handed: its local +x goes to
    /// `(cos, 0, -sin)`); 0 for a plate along the axes.
    pub pitch_rad: f32,
}

/// The sand's mean force on a moving plate over one window, as a vector.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct PlateForceSample {
    /// Position of the plate's centre in the middle of the window (m): the mean of its
    /// positions at the window's start and end.
    pub centre_m: [f64; 3],
    /// How far the plate has moved along its velocity at the end of the window (m).
    pub travelled_m: f64,
    /// Mean force of the sand on the plate over the window (N): impulse over its length.
    pub force_n: [f64; 3],
    /// Its component against the motion (N), summed substep by substep.
    pub force_against_motion_n: f64,
}

/// Moves the plate of `motion`, stepping `sand` with the CPIC coupling (one-way: the sand
/// feels the plate, the plate records what it would feel; the step also bounded by
/// [`Coupling::max_dt_s`]), and returns one sample per window: the distance travelled
/// (`depth_m`) and the sand's mean force against the motion (`force_n`, along `-velocity`).
pub fn move_plate(sand: &mut Solver, motion: &PlateMotion) -> Result<Vec<PlateSample>, SimError> {
    let samples = move_plate_forces(sand, motion)?;
    Ok(samples
        .iter()
        .map(|s| PlateSample {
            depth_m: s.travelled_m,
            force_n: s.force_against_motion_n,
        })
        .collect())
}

/// [`move_plate`] with the whole force and the plate's position of every window.
pub fn move_plate_forces(
    sand: &mut Solver,
    motion: &PlateMotion,
) -> Result<Vec<PlateForceSample>, SimError> {
    let mut bodies = RigidBodySet::new();
    let [x, y, z] = motion.start_m;
    let [vx, vy, vz] = motion.velocity_m_s;
    let start = Vec3::new(x, y, z);
    let velocity = Vec3::new(vx, vy, vz);
    // In f64, so that an axis-aligned motion gives an exact unit axis (the press's samples are
    // the bits they were).
    let [ux, uy, uz] = motion.velocity_m_s.map(f64::from);
    let speed = (ux * ux + uy * uy + uz * uz).sqrt();
    let direction = [ux / speed, uy / speed, uz / speed];
    let plate = bodies.insert(
        RigidBodyBuilder::kinematic_velocity_based()
            .pose(Pose::from_parts(
                start,
                rapier3d::glamx::Quat::from_rotation_y(motion.pitch_rad),
            ))
            .linvel(velocity),
    );
    let collider = SandCollider {
        name: "plate".into(),
        body: plate,
        body_to_surface: Pose::IDENTITY,
        surface: CpicSurface::thin_box(motion.half_extents_m),
        friction: motion.friction,
        mode: CouplingMode::OneWay,
    };
    let mut coupling = Coupling::new(vec![collider], &bodies).expect("one collider, in the set");
    let dx = sand.grid().dx;
    let end_s = sand.time_s + motion.duration_s;
    let mut samples = Vec::new();
    let mut window_end = sand.time_s;
    while window_end < end_s {
        window_end += motion.window_s;
        let centre_at_start = bodies[plate].translation();
        let (mut impulse_n_s, mut against_n_s, mut elapsed_s) = ([0.0f64; 3], 0.0f64, 0.0f64);
        while sand.time_s < window_end {
            let dt = sand.next_dt().min(coupling.max_dt_s(&bodies, dx));
            let impulses = coupling.substep(sand, &mut bodies, dt)?;
            let j = impulses[0].linear_n_s;
            against_n_s -= j.x * direction[0] + j.y * direction[1] + j.z * direction[2];
            for (sum, part) in impulse_n_s.iter_mut().zip([j.x, j.y, j.z]) {
                *sum += part;
            }
            elapsed_s += dt as f64;
            let rb = &mut bodies[plate];
            let moved = rb.translation() + rb.linvel() * dt;
            rb.set_translation(moved, true);
        }
        let centre = bodies[plate].translation();
        let moved = centre - start;
        let travelled_m = moved.x as f64 * direction[0]
            + moved.y as f64 * direction[1]
            + moved.z as f64 * direction[2];
        samples.push(PlateForceSample {
            centre_m: [
                0.5 * (centre_at_start.x as f64 + centre.x as f64),
                0.5 * (centre_at_start.y as f64 + centre.y as f64),
                0.5 * (centre_at_start.z as f64 + centre.z as f64),
            ],
            travelled_m,
            force_n: impulse_n_s.map(|j| j / elapsed_s),
            force_against_motion_n: against_n_s / elapsed_s,
        });
    }
    Ok(samples)
}

/// Mean force over each `cell_m` of depth from 0 to `final_depth_m`, at the cell's mid-depth.
/// The CPIC force saws with the grid period as the plate passes node planes (the set of
/// incompatible nodes changes at each plane; `docs/physics.md`), so fit these means, not the
/// raw samples. Cells without samples are left out.
pub fn depth_cell_means(
    samples: &[PlateSample],
    cell_m: f64,
    final_depth_m: f64,
) -> Vec<PlateSample> {
    let cells = (final_depth_m / cell_m).round() as usize;
    (0..cells)
        .filter_map(|c| {
            let (lo, hi) = (c as f64 * cell_m, (c + 1) as f64 * cell_m);
            let inside: Vec<f64> = samples
                .iter()
                .filter(|s| s.depth_m >= lo && s.depth_m < hi)
                .map(|s| s.force_n)
                .collect();
            (!inside.is_empty()).then(|| PlateSample {
                depth_m: 0.5 * (lo + hi),
                force_n: inside.iter().sum::<f64>() / inside.len() as f64,
            })
        })
        .collect()
}

/// A least-squares line `y = slope x + intercept` and its coefficient of determination.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LineFit {
    pub slope: f64,
    pub intercept: f64,
    /// `1 - SS_res / SS_tot`, with `SS_tot` about the mean of y.
    pub r_squared: f64,
}

/// Ordinary least squares through `(x, y)` points; with `through_origin` the intercept is held
/// at 0 (`slope = sum x y / sum x^2`). Needs two points with different x (one nonzero x
/// through the origin); NaN otherwise.
pub fn fit_line(points: &[(f64, f64)], through_origin: bool) -> LineFit {
    let n = points.len() as f64;
    let (mx, my) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (x, y)| (a + x / n, b + y / n));
    let (slope, intercept) = if through_origin {
        let sxy: f64 = points.iter().map(|(x, y)| x * y).sum();
        let sxx: f64 = points.iter().map(|(x, _)| x * x).sum();
        (sxy / sxx, 0.0)
    } else {
        let sxy: f64 = points.iter().map(|(x, y)| (x - mx) * (y - my)).sum();
        let sxx: f64 = points.iter().map(|(x, _)| (x - mx).powi(2)).sum();
        let slope = sxy / sxx;
        (slope, my - slope * mx)
    };
    let residual: f64 = points
        .iter()
        .map(|(x, y)| (y - slope * x - intercept).powi(2))
        .sum();
    let total: f64 = points.iter().map(|(_, y)| (y - my).powi(2)).sum();
    LineFit {
        slope,
        intercept,
        r_squared: 1.0 - residual / total,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fits_lines_with_and_without_intercept() {
        let points = [(1.0, 3.0), (2.0, 5.0), (3.0, 7.0)];
        let free = fit_line(&points, false);
        assert!((free.slope - 2.0).abs() < 1e-12 && (free.intercept - 1.0).abs() < 1e-12);
        assert!((free.r_squared - 1.0).abs() < 1e-12);
        let origin = fit_line(&points, true);
        // sum x y = 34, sum x^2 = 14.
        assert!((origin.slope - 34.0 / 14.0).abs() < 1e-12 && origin.intercept == 0.0);
        assert!(origin.r_squared < 1.0);
    }

    #[test]
    fn averages_samples_per_cell_of_depth() {
        let samples: Vec<PlateSample> = [(0.001, 1.0), (0.004, 3.0), (0.006, 10.0)]
            .iter()
            .map(|&(depth_m, force_n)| PlateSample { depth_m, force_n })
            .collect();
        let means = depth_cell_means(&samples, 0.005, 0.015);
        assert_eq!(means.len(), 2, "the empty third cell is left out");
        assert!((means[0].depth_m - 0.0025).abs() < 1e-12 && means[0].force_n == 2.0);
        assert!((means[1].depth_m - 0.0075).abs() < 1e-12 && means[1].force_n == 10.0);
    }
}
