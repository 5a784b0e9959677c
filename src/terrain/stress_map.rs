//! The RFT stress maps of MPM sand, measured as Li, Zhang and Goldman (2013, Fig. 2 and
//! supplement) measured theirs: a small plate at attack angle beta moved through the medium
//! along intrusion angle gamma (both as in [`super::rft`]); the stress per unit depth
//! `alpha_x, alpha_z` is the sand's force on the plate over its area and the depth of its
//! centre. Here the plate is leg-sized and a CPIC sheet ([`super::plate`]), moved through a
//! settled bed of the scene's sand; the force is fitted over the travel after it has built up.
//!
//! The maps are fitted with the generic Fourier form of [`super::stress_law`], its nine
//! coefficients free (N/m^3), by linear least squares: `alpha_z` on `1, cos 2b, sin(2b + g),
//! sin g, sin(-2b + g)` and `alpha_x` on `cos(2b + g), cos g, sin(-2b + g), sin 2b`.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use super::plate::{move_plate_forces, PlateForceSample, PlateMotion};
pub use super::stress_law::StressCoefficients;
use super::stress_law::{fourier_basis, StressTable, TableError, GENERIC};
use crate::mpm::{SimError, Solver};

/// The plate and its motion for one point of the maps.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct StressProbe {
    /// Length of the plate in the vertical plane of its motion (m): the leg's chord.
    pub chord_m: f32,
    /// Width of the plate across its motion, along y (m).
    pub width_m: f32,
    /// Thickness (m), below the grid spacing: a CPIC sheet.
    pub thickness_m: f32,
    /// Speed (m/s).
    pub speed_m_s: f32,
    /// Distance moved (m).
    pub travel_m: f32,
    /// The first part of the travel, while the force builds up, is not fitted (m).
    pub build_up_m: f32,
    /// Depth of the plate's highest point below the surface at its shallowest (m), > 0.
    pub min_depth_m: f32,
    /// The force is averaged over windows of this length (s).
    pub window_s: f64,
}

impl Default for StressProbe {
    /// The robot's leg (chord 4.1 cm, 1 cm wide, 3 mm thick) at 0.1 m/s, moved 3 cm, the
    /// last 2 cm fitted, its top edge at least 5 mm deep.
    fn default() -> Self {
        StressProbe {
            chord_m: 0.041,
            width_m: 0.01,
            thickness_m: 0.003,
            speed_m_s: 0.1,
            travel_m: 0.03,
            build_up_m: 0.01,
            min_depth_m: 0.005,
            window_s: 0.001,
        }
    }
}

/// One point of the maps.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StressPoint {
    /// Attack angle beta (deg).
    pub beta_deg: f64,
    /// Intrusion angle gamma (deg).
    pub gamma_deg: f64,
    /// Stress per unit depth against the horizontal motion (N/m^3; positive backward).
    pub alpha_x_n_m3: f64,
    /// Stress per unit depth upward (N/m^3).
    pub alpha_z_n_m3: f64,
    /// Depth of the plate's centre over the fitted travel, shallowest and deepest (m).
    pub depth_range_m: [f64; 2],
}

/// Where a probe starts and how it moves, for attack angle `beta_rad` and intrusion angle
/// `gamma_rad` about the point `(centre_x_m, centre_y_m)` of a surface at `surface_z_m`: the
/// plate's centre moves from `start` along `velocity`, its highest point at least
/// `min_depth_m` deep throughout and its path centred on the point horizontally.
pub fn probe_motion(
    probe: &StressProbe,
    [centre_x_m, centre_y_m, surface_z_m]: [f32; 3],
    beta_rad: f64,
    gamma_rad: f64,
    friction: f32,
) -> PlateMotion {
    let (sin_g, cos_g) = libm::sincos(gamma_rad);
    let half_chord = 0.5 * probe.chord_m as f64;
    let travel = probe.travel_m as f64;
    // The centre's depth where the plate is shallowest: the start going down, the end going up.
    let shallowest = probe.min_depth_m as f64 + half_chord * libm::sin(beta_rad).abs();
    let start_depth = shallowest + travel * (-sin_g).max(0.0);
    let start_x = centre_x_m as f64 - 0.5 * travel * cos_g;
    let speed = probe.speed_m_s as f64;
    PlateMotion {
        start_m: [
            start_x as f32,
            centre_y_m,
            (surface_z_m as f64 - start_depth) as f32,
        ],
        half_extents_m: [
            half_chord as f32,
            0.5 * probe.width_m,
            0.5 * probe.thickness_m,
        ],
        velocity_m_s: [(speed * cos_g) as f32, 0.0, (-speed * sin_g) as f32],
        duration_s: (travel / speed),
        window_s: probe.window_s,
        friction,
        // Turning about +y by -beta lays the chord along (cos b, 0, sin b).
        pitch_rad: -beta_rad as f32,
    }
}

/// Moves `probe` through `bed` (settled, its surface at `surface_m[2]`) at `beta_deg` and
/// `gamma_deg` and measures alpha: the least-squares slope through the origin of force
/// against `area x depth` over the windows after the build-up.
pub fn measure_point(
    bed: &mut Solver,
    surface_m: [f32; 3],
    probe: &StressProbe,
    [beta_deg, gamma_deg]: [f64; 2],
    friction: f32,
) -> Result<StressPoint, SimError> {
    let (beta_rad, gamma_rad) = (beta_deg.to_radians(), gamma_deg.to_radians());
    let motion = probe_motion(probe, surface_m, beta_rad, gamma_rad, friction);
    let samples = move_plate_forces(bed, &motion)?;
    let area = probe.chord_m as f64 * probe.width_m as f64;
    Ok(alpha_of(
        &samples,
        surface_m[2] as f64,
        area,
        probe.build_up_m as f64,
        [beta_deg, gamma_deg],
    ))
}

/// Alpha from a plate's force samples (module docs).
fn alpha_of(
    samples: &[PlateForceSample],
    surface_z_m: f64,
    area_m2: f64,
    build_up_m: f64,
    [beta_deg, gamma_deg]: [f64; 2],
) -> StressPoint {
    let fitted: Vec<(f64, [f64; 3])> = samples
        .iter()
        .filter(|s| s.travelled_m > build_up_m)
        .map(|s| (surface_z_m - s.centre_m[2], s.force_n))
        .collect();
    let depth_sq: f64 = fitted.iter().map(|(d, _)| d * d).sum();
    let slope = |axis: usize| fitted.iter().map(|(d, f)| d * f[axis]).sum::<f64>() / depth_sq;
    let (shallowest, deepest) = fitted
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), (d, _)| {
            (lo.min(*d), hi.max(*d))
        });
    StressPoint {
        beta_deg,
        gamma_deg,
        // Positive against the horizontal motion (+x).
        alpha_x_n_m3: -slope(0) / area_m2,
        alpha_z_n_m3: slope(2) / area_m2,
        depth_range_m: [shallowest, deepest],
    }
}

/// The generic form's functions at (beta, gamma) ([`fourier_basis`]).
fn basis(beta: f64, gamma: f64) -> [[f64; 5]; 2] {
    let (sin_2b, cos_2b) = libm::sincos(2.0 * beta);
    let (sin_g, cos_g) = libm::sincos(gamma);
    fourier_basis(cos_2b, sin_2b, cos_g, sin_g)
}

/// The least-squares fit of the generic form to `points`, and its root-mean-square residuals
/// `(alpha_x, alpha_z)` (N/m^3). Needs at least five points at angles that tell the functions
/// apart; None otherwise.
pub fn fit(points: &[StressPoint]) -> Option<(StressCoefficients, [f64; 2])> {
    let n = points.len();
    if n < 5 {
        return None;
    }
    let mut z_rows = DMatrix::zeros(n, 5);
    let mut x_rows = DMatrix::zeros(n, 4);
    for (i, p) in points.iter().enumerate() {
        let [z_basis, x_basis] = basis(p.beta_deg.to_radians(), p.gamma_deg.to_radians());
        for j in 0..5 {
            z_rows[(i, j)] = z_basis[j];
        }
        for j in 0..4 {
            x_rows[(i, j)] = x_basis[j];
        }
    }
    let z = DVector::from_iterator(n, points.iter().map(|p| p.alpha_z_n_m3));
    let x = DVector::from_iterator(n, points.iter().map(|p| p.alpha_x_n_m3));
    let solve = |rows: &DMatrix<f64>, rhs: &DVector<f64>| {
        let svd = rows.clone().svd(true, true);
        // A rank-deficient set of angles cannot fix every coefficient.
        let smallest = svd.singular_values.min();
        let largest = svd.singular_values.max();
        if smallest.is_nan() || smallest <= RANK_TOLERANCE * largest {
            return None;
        }
        svd.solve(rhs, 0.0).ok()
    };
    let (cz, cx) = (solve(&z_rows, &z)?, solve(&x_rows, &x)?);
    let rms = |rows: &DMatrix<f64>, c: &DVector<f64>, rhs: &DVector<f64>| {
        ((rows * c - rhs).norm_squared() / n as f64).sqrt()
    };
    let coefficients = StressCoefficients {
        a00: cz[0],
        a10: cz[1],
        b11: cz[2],
        b01: cz[3],
        bm11: cz[4],
        c11: cx[0],
        c01: cx[1],
        cm11: cx[2],
        d10: cx[3],
    };
    Some((coefficients, [rms(&x_rows, &cx, &x), rms(&z_rows, &cz, &z)]))
}

/// What `sandstep calibrate-rft --maps` measured (`--json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct StressMaps {
    /// Scene file the sand came from.
    pub scene: String,
    /// The sand material of the bed.
    pub material: String,
    /// Grid spacing (m).
    pub dx_m: f64,
    /// Particles in each bed.
    pub particles: usize,
    /// Height of the settled surface, from which depths are measured (m): the filled bed's
    /// top less what its top layer of particles sank while settling.
    pub settled_surface_m: f64,
    /// The plate and its motion.
    pub probe: StressProbe,
    /// The points, the fit and its check.
    #[serde(flatten)]
    pub fit: StressFit,
    /// Wall time of all the MPM runs (s).
    pub wall_time_s: f64,
}

/// A sand's stress maps as RFT reads them (`terrain.rft.stress_maps.file`), written by
/// `sandstep calibrate-rft <scene> --maps --write FILE` (YAML): the measured table and its
/// fit, with the sand and grid they were measured on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StressMapFile {
    /// The scene file the sand came from.
    pub scene: String,
    /// The material's name in that scene.
    pub material_name: String,
    /// The material as that scene defined it (its `sand.materials` entry): a scene using these
    /// maps must have a material of this name with exactly these settings.
    pub material: serde_yaml_ng::Value,
    /// Grid spacing of the MPM beds (m).
    pub dx_m: f32,
    /// The plate and its motion.
    pub probe: StressProbe,
    /// The measured alpha (N/m^3) on the grid of angles, to [`FILE_DIGITS`] significant
    /// digits.
    pub table: StressTable,
    /// The generic form fitted to the table (N/m^3).
    pub coefficients: StressCoefficients,
    /// Root-mean-square residual of the fit, `[alpha_x, alpha_z]` (N/m^3).
    pub rms_residual_n_m3: [f64; 2],
}

/// Significant digits of the values in a stress-map file: the measurement's noise is far
/// above the fourth digit.
pub const FILE_DIGITS: usize = 4;

/// `v` to [`FILE_DIGITS`] significant digits.
fn significant(v: f64) -> f64 {
    format!("{v:.*e}", FILE_DIGITS - 1).parse().unwrap_or(v)
}

/// The table of the grid `betas_deg` x `gammas_deg` (each sorted, repeats dropped), every
/// value `fill`.
fn table_of_grid(betas_deg: &[f64], gammas_deg: &[f64], fill: f64) -> StressTable {
    let sorted = |angles: &[f64]| {
        let mut v = angles.to_vec();
        v.sort_by(f64::total_cmp);
        v.dedup();
        v
    };
    let (betas_deg, gammas_deg) = (sorted(betas_deg), sorted(gammas_deg));
    let rows = vec![vec![fill; gammas_deg.len()]; betas_deg.len()];
    StressTable {
        betas_deg,
        gammas_deg,
        alpha_x_n_m3: rows.clone(),
        alpha_z_n_m3: rows,
    }
}

/// Whether points at `betas_deg` x `gammas_deg` form a table a stress-map file can hold
/// ([`StressTable::check`]): checked before minutes of measuring for `--write`.
pub fn check_table_grid(betas_deg: &[f64], gammas_deg: &[f64]) -> Result<(), TableError> {
    table_of_grid(betas_deg, gammas_deg, 0.0).check()
}

impl StressMaps {
    /// The maps as a file, with `material` (the scene's definition of [`Self::material`]).
    /// The fitted points must form a grid of betas and gammas a [`StressTable`] can hold.
    pub fn file(&self, material: serde_yaml_ng::Value) -> Result<StressMapFile, TableError> {
        let points = &self.fit.points;
        let betas: Vec<f64> = points.iter().map(|p| p.beta_deg).collect();
        let gammas: Vec<f64> = points.iter().map(|p| p.gamma_deg).collect();
        let mut table = table_of_grid(&betas, &gammas, f64::NAN);
        for p in points {
            let i = table.betas_deg.partition_point(|&b| b < p.beta_deg);
            let j = table.gammas_deg.partition_point(|&g| g < p.gamma_deg);
            table.alpha_x_n_m3[i][j] = significant(p.alpha_x_n_m3);
            table.alpha_z_n_m3[i][j] = significant(p.alpha_z_n_m3);
        }
        // A missing (beta, gamma) pair is left NaN, which the check names.
        table.check()?;
        Ok(StressMapFile {
            scene: self.scene.clone(),
            material_name: self.material.clone(),
            material,
            dx_m: self.dx_m as f32,
            probe: self.probe.clone(),
            table,
            coefficients: self.fit.coefficients.map(significant),
            rms_residual_n_m3: self.fit.rms_residual_n_m3.map(significant),
        })
    }
}

/// The generic form fitted to measured points, and checked on others.
#[derive(Clone, Debug, Serialize)]
pub struct StressFit {
    /// The fitted points.
    pub points: Vec<StressPoint>,
    /// The fitted coefficients (N/m^3).
    pub coefficients: StressCoefficients,
    /// The scale they give, `alpha_z(0, 90 deg)` (N/m^3).
    pub zeta_n_m3: f64,
    /// Root-mean-square residual of the fit over the points, `[alpha_x, alpha_z]` (N/m^3).
    pub rms_residual_n_m3: [f64; 2],
    /// The scale that fits Li et al.'s generic shape best to the points, alone (least
    /// squares over both alphas; N/m^3).
    pub generic_zeta_n_m3: f64,
    /// Root-mean-square residual of that generic shape: how far the sand's maps are from the
    /// shape RFT assumed before (N/m^3).
    pub generic_rms_residual_n_m3: [f64; 2],
    /// Points not fitted, each with the fit's alpha there.
    pub checks: Vec<StressCheck>,
}

/// A point not fitted, and what the fit gives there.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct StressCheck {
    /// The point as measured.
    pub measured: StressPoint,
    /// The fit's `alpha_x`, `alpha_z` at the point (N/m^3).
    pub fitted_n_m3: [f64; 2],
}

impl StressFit {
    /// The fit to `points`, checked on `checks`; None if the points cannot fix it ([`fit`]).
    pub fn of(points: Vec<StressPoint>, checks: &[StressPoint]) -> Option<StressFit> {
        let (coefficients, rms_residual_n_m3) = fit(&points)?;
        let zeta_n_m3 = coefficients.zeta_n_m3();
        // The generic shape's best scale: sum(shape x measured) / sum(shape^2).
        let unit = GENERIC;
        let (mut shape_measured, mut shape_sq) = (0.0, 0.0);
        for p in &points {
            let (x, z) = unit.alpha(p.beta_deg.to_radians(), p.gamma_deg.to_radians());
            shape_measured += x * p.alpha_x_n_m3 + z * p.alpha_z_n_m3;
            shape_sq += x * x + z * z;
        }
        let generic_zeta_n_m3 = shape_measured / shape_sq;
        let generic = GENERIC.scaled(generic_zeta_n_m3);
        let rms = |axis: usize| {
            let sum: f64 = points
                .iter()
                .map(|p| {
                    let (x, z) = generic.alpha(p.beta_deg.to_radians(), p.gamma_deg.to_radians());
                    let (model, measured) = if axis == 0 {
                        (x, p.alpha_x_n_m3)
                    } else {
                        (z, p.alpha_z_n_m3)
                    };
                    (model - measured).powi(2)
                })
                .sum();
            (sum / points.len() as f64).sqrt()
        };
        let checks = checks
            .iter()
            .map(|&measured| {
                let (x, z) = coefficients.alpha(
                    measured.beta_deg.to_radians(),
                    measured.gamma_deg.to_radians(),
                );
                StressCheck {
                    measured,
                    fitted_n_m3: [x, z],
                }
            })
            .collect();
        Some(StressFit {
            generic_zeta_n_m3,
            generic_rms_residual_n_m3: [rms(0), rms(1)],
            points,
            coefficients,
            zeta_n_m3,
            rms_residual_n_m3,
            checks,
        })
    }
}

/// Whether points at these angles (deg) fix the nine coefficients.
pub fn angles_fix_the_fit(angles_deg: &[(f64, f64)]) -> bool {
    let generic = GENERIC;
    let points: Vec<StressPoint> = angles_deg
        .iter()
        .map(|&(beta_deg, gamma_deg)| {
            let (x, z) = generic.alpha(beta_deg.to_radians(), gamma_deg.to_radians());
            StressPoint {
                beta_deg,
                gamma_deg,
                alpha_x_n_m3: x,
                alpha_z_n_m3: z,
                depth_range_m: [0.0; 2],
            }
        })
        .collect();
    fit(&points).is_some()
}

/// Singular values below this fraction of the largest make a fit's angles insufficient.
const RANK_TOLERANCE: f64 = 1e-6;

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(coefficients: &StressCoefficients) -> Vec<StressPoint> {
        let mut points = Vec::new();
        for beta_deg in [-60.0f64, -30.0, 0.0, 30.0, 60.0, 90.0] {
            for gamma_deg in [-90.0f64, -60.0, -30.0, 0.0, 30.0, 60.0, 90.0] {
                let (x, z) = coefficients.alpha(beta_deg.to_radians(), gamma_deg.to_radians());
                points.push(StressPoint {
                    beta_deg,
                    gamma_deg,
                    alpha_x_n_m3: x,
                    alpha_z_n_m3: z,
                    depth_range_m: [0.01, 0.02],
                });
            }
        }
        points
    }

    #[test]
    fn the_fit_recovers_the_coefficients_it_was_made_from() {
        let made = GENERIC.scaled(2.0e6);
        let (fitted, [rms_x, rms_z]) = fit(&grid(&made)).unwrap();
        let pairs = [
            (made.a00, fitted.a00),
            (made.a10, fitted.a10),
            (made.b11, fitted.b11),
            (made.b01, fitted.b01),
            (made.bm11, fitted.bm11),
            (made.c11, fitted.c11),
            (made.c01, fitted.c01),
            (made.cm11, fitted.cm11),
            (made.d10, fitted.d10),
        ];
        for (a, b) in pairs {
            assert!((a - b).abs() < 1e-6 * 2.0e6, "{a} vs {b}");
        }
        assert!(rms_x < 1e-3 && rms_z < 1e-3);
        // zeta is alpha_z straight down under a horizontal plate: the sum of A and B.
        assert!(
            (fitted.zeta_n_m3() - 2.0e6).abs() < 1.0,
            "{}",
            fitted.zeta_n_m3()
        );
    }

    #[test]
    fn only_grids_a_table_can_hold_may_be_written() {
        let gammas = [-90.0, -30.0, 30.0, 90.0];
        assert!(check_table_grid(&[-60.0, 0.0, 60.0, 90.0], &gammas).is_ok());
        // -90 and 90 deg are the same attack angle: one period holds only one of them.
        let both_ends = check_table_grid(&[-90.0, 0.0, 90.0], &gammas);
        assert_eq!(both_ends.unwrap_err().field, "betas_deg");
        let short = check_table_grid(&[0.0, 45.0], &[-45.0, 0.0, 90.0]);
        assert_eq!(short.unwrap_err().field, "gammas_deg");
    }

    #[test]
    fn too_few_or_degenerate_angles_give_no_fit() {
        let points = grid(&GENERIC);
        assert!(fit(&points[..4]).is_none());
        // One gamma only: sin g and the constant cannot be told apart.
        let one_gamma: Vec<StressPoint> = points
            .iter()
            .filter(|p| p.gamma_deg == 30.0)
            .copied()
            .collect();
        assert!(fit(&one_gamma).is_none());
    }

    #[test]
    fn alpha_is_force_over_area_and_depth_after_the_build_up() {
        // A plate 2 cm deep then 3 cm deep feeling 1 N and 1.5 N up, 0.5 and 0.75 N back.
        let sample = |travelled_m, depth_m: f64, force_n| PlateForceSample {
            centre_m: [0.0, 0.0, 0.1 - depth_m],
            travelled_m,
            force_n,
            force_against_motion_n: 0.0,
        };
        let samples = [
            sample(0.001, 0.01, [9.0, 0.0, 9.0]),
            sample(0.02, 0.02, [-0.5, 0.0, 1.0]),
            sample(0.03, 0.03, [-0.75, 0.0, 1.5]),
        ];
        let p = alpha_of(&samples, 0.1, 2.0e-4, 0.01, [0.0, 30.0]);
        assert!((p.alpha_z_n_m3 - 1.0 / (2.0e-4 * 0.02)).abs() < 1e-6);
        assert!((p.alpha_x_n_m3 - 0.5 / (2.0e-4 * 0.02)).abs() < 1e-6);
        assert!((p.depth_range_m[0] - 0.02).abs() < 1e-12);
        assert!((p.depth_range_m[1] - 0.03).abs() < 1e-12);
    }

    #[test]
    fn the_probe_rises_towards_the_front_for_positive_beta() {
        use rapier3d::glamx::{Quat, Vec3};
        let probe = StressProbe::default();
        for beta in [0.4f64, -0.9, 1.3] {
            let m = probe_motion(&probe, [0.1, 0.05, 0.08], beta, 0.0, 0.3);
            let chord = Quat::from_rotation_y(m.pitch_rad) * Vec3::X;
            let expected = Vec3::new(libm::cos(beta) as f32, 0.0, libm::sin(beta) as f32);
            assert!((chord - expected).length() < 1e-6, "{beta}: {chord:?}");
            assert!(m.velocity_m_s[0] > 0.0, "gamma 0 moves along +x");
        }
    }

    #[test]
    fn the_probe_stays_below_the_surface_and_centred() {
        let probe = StressProbe::default();
        for (beta, gamma) in [(0.5, 1.2), (-1.0, -1.5), (1.5, 0.0)] {
            let m = probe_motion(&probe, [0.1, 0.05, 0.08], beta, gamma, 0.3);
            let end_z = m.start_m[2] + m.velocity_m_s[2] * m.duration_s as f32;
            let half_rise = 0.5 * probe.chord_m * libm::sinf(beta as f32).abs();
            let top = m.start_m[2].max(end_z) + half_rise;
            assert!(
                top <= 0.08 - probe.min_depth_m + 1e-6,
                "{beta} {gamma}: {top}"
            );
            let end_x = m.start_m[0] + m.velocity_m_s[0] * m.duration_s as f32;
            assert!((0.5 * (m.start_m[0] + end_x) - 0.1).abs() < 1e-6);
        }
    }
}
