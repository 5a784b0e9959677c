//! The bed of `sandstep calibrate-rft`: a settled square of the scene's sand in a box with slip
//! walls (`terrain.rft.calibration`), on which [`crate::terrain::calibration`] presses its
//! plate.

use std::path::{Path, PathBuf};

use super::config::{
    BodyConfig, BoxShape, DomainConfig, SandConfig, SolverConfig, WallConfig, WallsConfig,
};
use super::{Scene, SceneError};
use crate::mpm::{SimError, Solver, Wall};
use crate::progress::Progress;
use crate::terrain::blade::{check, drag_blade, half_means, BladeDrag, BladeDragResult};
use crate::terrain::calibration::{calibrate, RftCalibration};
use crate::terrain::stress_map::{angles_fix_the_fit, measure_point, StressFit, StressMaps};
use crate::terrain::TerrainConfig;

/// Errors of a calibration.
#[derive(thiserror::Error, Debug)]
pub enum CalibrationError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Sim(#[from] SimError),
    /// An option of `sandstep drag-blade` out of range (the message names it).
    #[error("{0}")]
    Option(String),
    /// The stress maps could not be written as a file.
    #[error("cannot write the stress maps to {path}: {message}")]
    WriteMaps { path: PathBuf, message: String },
}

/// Room above a stress-map bed for heaved sand, in plate chords.
const STRESS_MAP_HEADROOM_CHORDS: f32 = 0.5;

/// Mean height of the highest particles of a bed of `size_m` (length, width, depth from the
/// origin), one layer's worth: its particles over its layers, the depth over the particles'
/// spacing (m).
fn top_layer_height_m(bed: &Solver, size_m: [f32; 3]) -> f32 {
    let mut heights: Vec<f32> = bed.particles.position.iter().map(|p| p.z).collect();
    let count = heights.len();
    let [length, width, depth] = size_m;
    let spacing = libm::cbrtf(length * width * depth / count as f32);
    let layers = (depth / spacing).round().max(1.0) as usize;
    let layer = (count / layers).max(1);
    heights.select_nth_unstable_by(count - layer, f32::total_cmp);
    heights[count - layer..].iter().sum::<f32>() / layer as f32
}

impl Scene {
    /// The plate test's bed of `terrain.rft.calibration`, at rest and unsettled, and the name of
    /// its material: the calibration's `material`, else the first sand body's.
    pub fn rft_calibration_bed(&self) -> Result<(Solver, String), SceneError> {
        let c = &self.config.terrain.rft.calibration;
        let size_m = [c.bed_side_m, c.bed_side_m, c.bed_depth_m];
        // Room for heaved sand: one plate side above the surface.
        self.calibration_bed(size_m, c.plate_side_m, c.dx_m)
    }

    /// A bed of the calibration's material, `size_m` (x, y, depth, from the origin) on a grid
    /// of `dx_m`, with `headroom_m` above its surface, at rest and unsettled.
    fn calibration_bed(
        &self,
        size_m: [f32; 3],
        headroom_m: f32,
        dx_m: f32,
    ) -> Result<(Solver, String), SceneError> {
        let c = &self.config.terrain.rft.calibration;
        let sand = self.sand().ok_or_else(|| {
            self.invalid(
                "terrain.rft.calibration",
                "needs a `sand` section with the material to calibrate",
            )
        })?;
        let material = match &c.material {
            Some(name) => name.clone(),
            None => sand
                .bodies
                .first()
                .map(|b| b.material.clone())
                .or_else(|| sand.materials.keys().next().cloned())
                .ok_or_else(|| {
                    self.invalid(
                        "terrain.rft.calibration.material",
                        "no sand material to use",
                    )
                })?,
        };
        // The lattice of the scene's body of that material (else its first body).
        let particles_per_cell = sand
            .bodies
            .iter()
            .find(|b| b.material == material)
            .or(sand.bodies.first())
            .map(|b| b.particles_per_cell)
            .ok_or_else(|| self.invalid("sand.bodies", "no sand body to take the lattice from"))?;
        let slip = WallConfig(Wall::Slip);
        let mut config = self.config.clone();
        config.robot = None;
        config.column_collapse = None;
        config.terrain = TerrainConfig::default();
        config.sand = Some(SandConfig {
            domain: DomainConfig {
                min_m: [0.0; 3],
                max_m: [size_m[0], size_m[1], size_m[2] + headroom_m],
                walls: WallsConfig::all(slip),
            },
            dx_m,
            // All sand awake: a sleeping block is a rigid support, which would stiffen the
            // bed under the plate; the scene's other solver settings are kept.
            solver: SolverConfig {
                fixed_dt_s: None,
                sleep: None,
                ..sand.solver.clone()
            },
            materials: [(material.clone(), sand.materials[&material].clone())].into(),
            window: None,
            bodies: vec![BodyConfig {
                material: material.clone(),
                box_shape: Some(BoxShape {
                    min_m: [0.0; 3],
                    max_m: size_m,
                }),
                cylinder: None,
                particles_per_cell,
                velocity_m_s: [0.0; 3],
            }],
        });
        let bed = Scene {
            file: self.file.clone(),
            config,
        };
        bed.validate().map_err(|e| {
            self.invalid(
                "terrain.rft.calibration",
                format!("the plate test's bed is not a valid scene: {e}"),
            )
        })?;
        let solver = bed.build_solver().expect("the bed scene has sand");
        Ok((solver, material))
    }

    /// `sandstep calibrate-rft`: the plate test of `terrain.rft.calibration` on this scene's
    /// sand, and zeta fitted to it.
    pub fn calibrate_rft(&self) -> Result<RftCalibration, CalibrationError> {
        let (mut bed, material) = self.rft_calibration_bed()?;
        Ok(calibrate(
            &mut bed,
            &self.config.terrain.rft.calibration,
            self.config.coupling.friction,
            self.file.display().to_string(),
            material,
        )?)
    }

    /// `sandstep calibrate-rft --maps`: RFT's stress maps measured on this scene's sand
    /// (`terrain.rft.calibration.maps`), each point on a fresh bed settled for the
    /// calibration's `settle_s`, and fitted; `progress` hears of every point.
    pub fn rft_stress_maps(&self, progress: &Progress) -> Result<StressMaps, CalibrationError> {
        let c = &self.config.terrain.rft.calibration;
        let maps = &c.maps;
        let dx_m = match (maps.dx_m, self.sand()) {
            (Some(dx), _) => dx,
            (None, Some(sand)) => sand.dx_m,
            (None, None) => c.dx_m,
        };
        let invalid = |field: &str, message: String| {
            let field = format!("terrain.rft.calibration.maps.{field}");
            CalibrationError::Scene(self.invalid(field, message))
        };
        let probe = &maps.probe;
        if probe.thickness_m >= dx_m {
            return Err(invalid(
                "probe.thickness_m",
                format!(
                    "{} must be below the grid spacing {dx_m} m (a CPIC sheet)",
                    probe.thickness_m
                ),
            ));
        }
        // The plate's path, whatever the angles, stays a cell from the bed's walls and floor.
        let [length, width, depth] = maps.bed_m;
        let reach = [
            (
                "bed_m.0",
                probe.travel_m + probe.chord_m + 2.0 * dx_m,
                length,
            ),
            ("bed_m.1", probe.width_m + 2.0 * dx_m, width),
            (
                "bed_m.2",
                probe.min_depth_m + probe.chord_m + probe.travel_m + dx_m,
                depth,
            ),
        ];
        for (field, needed, side) in reach {
            if side < needed {
                return Err(invalid(
                    field,
                    format!(
                        "{side} m is too small: the plate's path, a cell from every wall and \
                         the floor, needs {needed} m"
                    ),
                ));
            }
        }
        let fitted_angles: Vec<(f64, f64)> = maps
            .betas_deg
            .iter()
            .flat_map(|&b| maps.gammas_deg.iter().map(move |&g| (b, g)))
            .collect();
        if !angles_fix_the_fit(&fitted_angles) {
            return Err(invalid(
                "betas_deg",
                "with gammas_deg, does not fix the nine coefficients of the fit (take at least \
                 three different betas, -90 and 90 counting as one, and three gammas)"
                    .into(),
            ));
        }
        let wall = std::time::Instant::now();
        // The fitted points, then the checks.
        let angles: Vec<(f64, f64, bool)> = fitted_angles
            .iter()
            .map(|&(b, g)| (b, g, true))
            .chain(maps.check_deg.iter().map(|&[b, g]| (b, g, false)))
            .collect();
        let duration_s = c.settle_s + (probe.travel_m / probe.speed_m_s) as f64;
        progress.plan(&vec![duration_s; angles.len()]);
        let (mut fitted, mut checked) = (Vec::new(), Vec::new());
        let mut material = String::new();
        let (mut particles, mut surface_z_m) = (0, depth);
        for (beta_deg, gamma_deg, is_fitted) in angles {
            let name = format!("beta {beta_deg} deg, gamma {gamma_deg} deg");
            progress.start_run(&name, Some(duration_s));
            let headroom_m = STRESS_MAP_HEADROOM_CHORDS * probe.chord_m;
            let (mut bed, bed_material) = self.calibration_bed(maps.bed_m, headroom_m, dx_m)?;
            (material, particles) = (bed_material, bed.particles.len());
            let top_before_m = top_layer_height_m(&bed, maps.bed_m);
            bed.advance_to(c.settle_s)?;
            // Depth is measured from the settled surface: the filled top, less what the top
            // layer of particles sank while settling.
            surface_z_m = depth - (top_before_m - top_layer_height_m(&bed, maps.bed_m));
            let point = measure_point(
                &mut bed,
                [0.5 * length, 0.5 * width, surface_z_m],
                probe,
                [beta_deg, gamma_deg],
                self.config.coupling.friction,
            )?;
            progress.finish_run(
                duration_s,
                &format!(
                    "{name}: alpha_x {:.3e}, alpha_z {:.3e} N/m^3",
                    point.alpha_x_n_m3, point.alpha_z_n_m3
                ),
            );
            if is_fitted { &mut fitted } else { &mut checked }.push(point);
        }
        progress.done();
        let fit = StressFit::of(fitted, &checked)
            .ok_or_else(|| invalid("betas_deg", "the measured points do not fix the fit".into()))?;
        Ok(StressMaps {
            scene: self.file.display().to_string(),
            material,
            dx_m: dx_m as f64,
            particles,
            settled_surface_m: surface_z_m as f64,
            probe: probe.clone(),
            fit,
            wall_time_s: wall.elapsed().as_secs_f64(),
        })
    }

    /// `sandstep drag-blade`: `blade` dragged through the plate test's bed of
    /// `terrain.rft.calibration` (its sand, grid and bed), with the scene's sand-robot friction.
    pub fn drag_blade(&self, blade: &BladeDrag) -> Result<BladeDragResult, CalibrationError> {
        let c = &self.config.terrain.rft.calibration;
        check(blade, c).map_err(CalibrationError::Option)?;
        let wall = std::time::Instant::now();
        let (mut bed, material) = self.rft_calibration_bed()?;
        let (samples, substeps) = drag_blade(&mut bed, c, blade, self.config.coupling.friction)?;
        let (first_half_force_n, second_half_force_n) = half_means(&samples);
        Ok(BladeDragResult {
            scene: self.file.display().to_string(),
            material,
            blade: blade.clone(),
            dx_m: c.dx_m as f64,
            bed_side_m: c.bed_side_m as f64,
            bed_depth_m: c.bed_depth_m as f64,
            particles: bed.particles.len(),
            substeps,
            first_half_force_n,
            second_half_force_n,
            samples,
            wall_time_s: wall.elapsed().as_secs_f64(),
        })
    }

    /// Writes `maps`, measured on this scene's sand, to `path` as a stress-map file
    /// ([`crate::terrain::stress_map::StressMapFile`]) with the material's definition and a
    /// comment on top saying what it is and how it was made.
    pub fn write_stress_maps(
        &self,
        maps: &StressMaps,
        path: &Path,
    ) -> Result<(), CalibrationError> {
        let fail = |message: String| CalibrationError::WriteMaps {
            path: path.to_path_buf(),
            message,
        };
        let material = self
            .sand()
            .and_then(|sand| sand.materials.get(&maps.material))
            .ok_or_else(|| fail(format!("the scene has no material `{}`", maps.material)))?;
        // Through text, so that f32 settings are written as they read (0.3, not 0.30000001).
        let material = serde_yaml_ng::to_string(material)
            .and_then(|text| serde_yaml_ng::from_str(&text))
            .map_err(|e| fail(e.to_string()))?;
        let file = maps.file(material).map_err(|e| {
            fail(format!(
                "terrain.rft.calibration.maps: the fitted angles do not form a table: {e}"
            ))
        })?;
        let header = format!(
            "# RFT stress maps of the MPM sand: material `{}` of {}, dx {} m, measured by\n\
             # `sandstep calibrate-rft {} --maps --write {}` ({:.0} s of wall time).\n\
             # Use: terrain.rft.stress_maps.file in a scene with this material. Angles in deg, \
             alpha in N/m^3;\n\
             # table rows are betas_deg, columns gammas_deg (docs/physics.md, \"Stress maps\").\n",
            maps.material,
            maps.scene,
            maps.dx_m as f32,
            maps.scene,
            path.display(),
            maps.wall_time_s
        );
        let body = serde_yaml_ng::to_string(&file).map_err(|e| fail(e.to_string()))?;
        crate::files::write_atomically(path, (header + &body).as_bytes())
            .map_err(|e| fail(e.to_string()))
    }
}
