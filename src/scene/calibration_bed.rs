//! The bed of `sandstep calibrate-rft`: a settled square of the scene's sand in a box with slip
//! walls (`terrain.rft.calibration`), on which [`crate::terrain::calibration`] presses its
//! plate.

use super::config::{
    BodyConfig, BoxShape, DomainConfig, SandConfig, SolverConfig, WallConfig, WallsConfig,
};
use super::{Scene, SceneError};
use crate::mpm::{SimError, Solver, Wall};
use crate::terrain::blade::{check, drag_blade, half_means, BladeDrag, BladeDragResult};
use crate::terrain::calibration::{calibrate, RftCalibration};
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
}

impl Scene {
    /// The plate test's bed of `terrain.rft.calibration`, at rest and unsettled, and the name of
    /// its material: the calibration's `material`, else the first sand body's.
    pub fn rft_calibration_bed(&self) -> Result<(Solver, String), SceneError> {
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
                // Room for heaved sand: one plate side above the surface.
                max_m: [c.bed_side_m, c.bed_side_m, c.bed_depth_m + c.plate_side_m],
                walls: WallsConfig::all(slip),
            },
            dx_m: c.dx_m,
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
                    max_m: [c.bed_side_m, c.bed_side_m, c.bed_depth_m],
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
}
