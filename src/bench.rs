//! `sandstep bench`: throughput of the sand substep on a 3D block collapsing under gravity.

use std::time::Instant;

use nalgebra::Vector3;
use serde::Serialize;
use serde_json::{Map, Value};

use crate::mpm::kernel::Kernel;
use crate::mpm::material::{Constitutive, DruckerPrager, Lame};
use crate::mpm::simd::InstructionSet;
use crate::mpm::{
    CpicBand, NewParticle, Solver, SolverMaterial, SolverSettings, TimeStep, Transfer, Wall, Walls,
    DEFAULT_CPIC_BAND_RELAXATION_S, DEFAULT_FLIP_RELAXATION_S,
};

/// Benchmark sand: Klar et al. (2016) parameters.
const DENSITY_KG_M3: f32 = 2200.0;
const YOUNGS_MODULUS_PA: f32 = 3.537e5;
const POISSON_RATIO: f32 = 0.3;
const FRICTION_ANGLE_DEG: f32 = 35.0;
/// Grid spacing of the benchmark (m); the block's size follows from the particle count.
const DX_M: f32 = 0.01;
/// Particles per cell edge (8 per cell).
const PARTICLES_PER_EDGE: usize = 2;
/// Substeps run before timing starts, so the block is already moving and sorted.
const WARMUP_STEPS: u64 = 5;

/// What `sandstep bench --json` prints.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub particles: usize,
    pub threads: usize,
    /// Instruction set of the wide loops (`avx512`, `avx2`, `portable`).
    pub instruction_set: String,
    /// Lanes of the wide loops.
    pub lanes: usize,
    pub steps: u64,
    pub wall_time_s: f64,
    /// Particle-substeps per wall-clock second, whole substep.
    pub particle_steps_per_s: f64,
    /// Particle-substeps per second of each stage on its own.
    pub stages: Map<String, Value>,
    /// Bytes of particles, grid and scratch per particle.
    pub bytes_per_particle: f64,
    pub dx_m: f32,
}

/// A cube of sand of about `particles` particles at 8 per cell, resting on the floor of a box
/// twice its width, released at t = 0.
pub fn sand_block(particles: usize) -> Solver {
    let cells_per_edge =
        libm::cbrt((particles / PARTICLES_PER_EDGE.pow(3)) as f64).round() as usize;
    let n = cells_per_edge * PARTICLES_PER_EDGE;
    let side = cells_per_edge as f32 * DX_M;
    let domain = Vector3::new(2.0 * side, 2.0 * side, 1.5 * side);
    let lame = Lame::from_young_poisson(YOUNGS_MODULUS_PA, POISSON_RATIO);
    let material = SolverMaterial {
        name: "sand".into(),
        density_kg_m3: DENSITY_KG_M3,
        model: Constitutive::DruckerPrager(DruckerPrager::new(
            lame,
            FRICTION_ANGLE_DEG.to_radians(),
            true,
        )),
    };
    let settings = SolverSettings {
        dx: DX_M,
        domain_min: Vector3::zeros(),
        domain_max: domain,
        walls: Walls {
            z_min: Wall::Sticky,
            ..Walls::all(Wall::Slip)
        },
        gravity: Vector3::new(0.0, 0.0, -9.81),
        time_step: TimeStep::Adaptive {
            cfl: 0.4,
            max_dt_s: 1e-3,
        },
        blowup_speed_m_s: 100.0,
        transfer: Transfer::default(),
        flip_relaxation_s: DEFAULT_FLIP_RELAXATION_S,
        cpic_band: CpicBand::default(),
        cpic_band_relaxation_s: DEFAULT_CPIC_BAND_RELAXATION_S,
        kernel: Kernel::QuadraticBspline,
        sleep: None,
    };
    let mut solver = Solver::new(settings, vec![material]);
    let spacing = DX_M / PARTICLES_PER_EDGE as f32;
    let volume = spacing.powi(3);
    let corner = Vector3::new(0.5 * side, 0.5 * side, 0.0);
    let mut new = Vec::with_capacity(n * n * n);
    for i in 0..n {
        for j in 0..n {
            for k in 0..n {
                let offset = Vector3::new(i as f32, j as f32, k as f32).add_scalar(0.5) * spacing;
                new.push(NewParticle {
                    position: corner + offset,
                    velocity: Vector3::zeros(),
                    mass: DENSITY_KG_M3 * volume,
                    volume,
                    material: 0,
                });
            }
        }
    }
    solver.add_particles(new);
    solver
}

/// Runs the benchmark on the current rayon pool with the wide loops on `instruction_set`.
pub fn run(
    particles: usize,
    steps: u64,
    instruction_set: InstructionSet,
) -> Result<BenchReport, crate::mpm::SimError> {
    let mut solver = sand_block(particles);
    solver.set_instruction_set(instruction_set);
    // On a worker of the pool, as a simulation's substeps run (`Simulation::advance_to`).
    let wall_time_s = rayon::scope(|_| {
        for _ in 0..WARMUP_STEPS {
            solver.substep()?;
        }
        solver.stage_times = Default::default();
        let start = Instant::now();
        for _ in 0..steps {
            solver.substep()?;
        }
        Ok(start.elapsed().as_secs_f64())
    })?;
    let n = solver.particles.len();
    let work = (n as u64 * steps) as f64;
    let stages = solver
        .stage_times
        .named()
        .iter()
        .map(|(name, t)| {
            (
                name.to_string(),
                Value::from(work / t.as_secs_f64().max(1e-12)),
            )
        })
        .collect();
    Ok(BenchReport {
        particles: n,
        threads: rayon::current_num_threads(),
        instruction_set: instruction_set.name().to_string(),
        lanes: instruction_set.lanes(),
        steps,
        wall_time_s,
        particle_steps_per_s: work / wall_time_s,
        stages,
        bytes_per_particle: solver.memory_bytes() as f64 / n as f64,
        dx_m: DX_M,
    })
}
