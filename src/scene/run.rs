//! Running a scene headless: frames, progress, snapshots and the summary.

use std::path::PathBuf;
use std::time::Instant;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use serde_json::{json, Map, Value};

use super::Scene;
use crate::analysis::collapse::{self, CollapseGeometry};
use crate::mpm::{SimError, Solver};
use crate::robot::{RobotConfig, RobotError, RobotSim};

/// How to run a scene.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Overrides the scene's `duration_s` (s).
    pub duration_s: Option<f64>,
    /// Directory for snapshots; default `out/<scene name>`.
    pub out_dir: Option<PathBuf>,
    /// Show a progress bar on stderr.
    pub progress: bool,
}

/// What a run reports (`sandstep run --json` prints it).
#[derive(Clone, Debug, Serialize)]
pub struct RunSummary {
    pub scene: String,
    pub steps: u64,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    pub particles: usize,
    pub particle_steps_per_s: f64,
    /// Wall time per simulated second (s/s).
    pub wall_time_per_sim_s: f64,
    /// Wall time of each substep stage (s).
    pub stage_times_s: Map<String, Value>,
    /// Scene-specific measurements (see `docs/scenes.md`).
    pub metrics: Map<String, Value>,
}

#[derive(thiserror::Error, Debug)]
pub enum RunError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Robot(#[from] RobotError),
    #[error("scene {0} has nothing to simulate (no `sand` or `robot` section)")]
    Empty(String),
    #[error(transparent)]
    Coupling(#[from] crate::coupling::CouplingError),
}

/// Runs a scene to its end and measures it.
pub fn run_scene(scene: &Scene, opts: &RunOptions) -> Result<RunSummary, RunError> {
    if let Some(robot) = &scene.config.robot {
        return match scene.config.sand {
            None => run_robot_on_ground(scene, robot, opts),
            Some(_) => super::robot_sand::run_robot_on_sand(scene, robot, opts),
        };
    }
    let config = &scene.config;
    let mut solver = scene
        .build_solver()
        .ok_or_else(|| RunError::Empty(scene.file.display().to_string()))?;
    let duration = opts.duration_s.unwrap_or(config.duration_s);
    let frame_interval = config.output.frame_interval_s;
    let frames = (duration / frame_interval).ceil().max(1.0) as u64;
    let collapse = collapse_geometry(scene);
    let initial = collapse.map(|g| collapse::measure(&g, &solver.particles.position));

    let out_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&config.name));
    let ply_every = config.output.ply_every_frames as u64;
    if ply_every > 0 {
        std::fs::create_dir_all(&out_dir).map_err(|source| RunError::Write {
            path: out_dir.clone(),
            source,
        })?;
        write_snapshot(&out_dir, 0, &solver)?;
    }

    let bar = progress_bar(opts.progress, duration);
    let wall = Instant::now();
    let mut particle_steps = 0u64;
    for frame in 1..=frames {
        let target = (frame as f64 * frame_interval).min(duration);
        let steps = solver.advance_to(target).inspect_err(|_| bar.abandon())?;
        particle_steps += steps * solver.particles.len() as u64;
        bar.set_position((target * 1000.0) as u64);
        bar.set_message(format!(
            "step {} dt {:.2e} s",
            solver.steps,
            solver.next_dt()
        ));
        if ply_every > 0 && frame % ply_every == 0 {
            write_snapshot(&out_dir, frame, &solver)?;
        }
    }
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();

    let mut metrics = Map::new();
    if let (Some(g), Some(initial)) = (collapse, initial) {
        let last = collapse::measure(&g, &solver.particles.position);
        let cc = config
            .column_collapse
            .as_ref()
            .expect("collapse geometry implies the section");
        let normalized = (last.length_m - initial.length_m) / initial.length_m;
        metrics.insert(
            "aspect_ratio".into(),
            json!(initial.height_m / initial.length_m),
        );
        metrics.insert("initial_length_m".into(), json!(initial.length_m));
        metrics.insert("initial_height_m".into(), json!(initial.height_m));
        metrics.insert("runout_m".into(), json!(last.length_m));
        metrics.insert("final_height_m".into(), json!(last.height_m));
        metrics.insert("normalized_runout".into(), json!(normalized));
        metrics.insert(
            "lube_2005_normalized_runout".into(),
            json!(collapse::lube_normalized_runout(cc.aspect_ratio)),
        );
    }
    metrics.insert("total_mass_kg".into(), json!(solver.particles.total_mass()));
    Ok(RunSummary::of_solver(
        &config.name,
        &solver,
        wall_time_s,
        particle_steps,
        metrics,
    ))
}

/// The robot alone on rigid ground (rapier only).
fn run_robot_on_ground(
    scene: &Scene,
    robot: &RobotConfig,
    opts: &RunOptions,
) -> Result<RunSummary, RunError> {
    let config = &scene.config;
    let mut sim = RobotSim::new(robot, config.gravity_m_s2)?;
    let duration = opts.duration_s.unwrap_or(config.duration_s);
    let frame_interval = config.output.frame_interval_s;
    let frames = (duration / frame_interval).ceil().max(1.0) as u64;
    let bar = progress_bar(opts.progress, duration);
    let wall = Instant::now();
    let mut steps = 0u64;
    for frame in 1..=frames {
        let target = (frame as f64 * frame_interval).min(duration);
        let dt = target - sim.time_s();
        // RobotSim::step takes ceil(dt / max_dt_s) rapier steps.
        steps += (dt / robot.physics.max_dt_s).ceil().max(1.0) as u64;
        sim.step(dt as f32);
        bar.set_position((target * 1000.0) as u64);
    }
    bar.finish_and_clear();
    let wall_time_s = wall.elapsed().as_secs_f64();
    let metrics = robot_metrics_json(&sim);
    Ok(RunSummary {
        scene: config.name.clone(),
        steps,
        sim_time_s: sim.time_s(),
        wall_time_s,
        particles: 0,
        particle_steps_per_s: 0.0,
        wall_time_per_sim_s: wall_time_s / sim.time_s().max(1e-12),
        stage_times_s: Map::new(),
        metrics,
    })
}

/// Where the column of a `column_collapse` scene stands.
pub fn collapse_geometry(scene: &Scene) -> Option<CollapseGeometry> {
    let cc = scene.config.column_collapse.as_ref()?;
    let sand = scene.sand()?;
    Some(CollapseGeometry {
        wall_x: sand.domain.min_m[0],
        floor_z: sand.domain.min_m[2],
        width: sand.domain.max_m[1] - sand.domain.min_m[1],
        dx: sand.dx_m,
        particles_per_cell: cc.particles_per_cell,
    })
}

fn write_snapshot(dir: &std::path::Path, frame: u64, solver: &Solver) -> Result<(), RunError> {
    let path = dir.join(format!("particles_{frame:05}.ply"));
    super::ply::write_ply(&path, &solver.particles)
        .map_err(|source| RunError::Write { path, source })
}

impl RunSummary {
    /// The summary of a run of `solver` that took `particle_steps` particle-steps.
    pub(super) fn of_solver(
        scene: &str,
        solver: &Solver,
        wall_time_s: f64,
        particle_steps: u64,
        metrics: Map<String, Value>,
    ) -> Self {
        RunSummary {
            scene: scene.to_string(),
            steps: solver.steps,
            sim_time_s: solver.time_s,
            wall_time_s,
            particles: solver.particles.len(),
            particle_steps_per_s: particle_steps as f64 / wall_time_s.max(1e-9),
            wall_time_per_sim_s: wall_time_s / solver.time_s.max(1e-12),
            stage_times_s: solver
                .stage_times
                .named()
                .iter()
                .map(|(name, t)| (name.to_string(), json!(t.as_secs_f64())))
                .collect(),
            metrics,
        }
    }
}

/// The robot's metrics as a JSON map.
pub(super) fn robot_metrics_json(robot: &RobotSim) -> Map<String, Value> {
    match serde_json::to_value(robot.metrics()).expect("plain data") {
        Value::Object(map) => map,
        _ => unreachable!("metrics serialise as a map"),
    }
}

pub(super) fn progress_bar(visible: bool, duration_s: f64) -> ProgressBar {
    let bar = ProgressBar::with_draw_target(
        Some((duration_s * 1000.0) as u64),
        if visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        },
    );
    bar.set_style(
        ProgressStyle::with_template(
            "{elapsed_precise} [{bar:40}] {pos}/{len} ms sim, eta {eta} ({msg})",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    bar
}
