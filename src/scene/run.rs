//! Running a scene headless: frames, progress, snapshots and the summary.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use serde::Serialize;
use serde_json::{json, Map, Value};

use super::error::{ObserverError, RunError};
use super::simulation::Simulation;
use super::Scene;
use crate::analysis::collapse::{self, CollapseGeometry};
use crate::mpm::lattice::Lattice;
use crate::progress::Progress;
use crate::robot::RobotSim;

/// How to run a scene.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Overrides the scene's `duration_s` (s).
    pub duration_s: Option<f64>,
    /// Directory for snapshots; default `out/<scene name>`.
    pub out_dir: Option<PathBuf>,
    /// Where the run reports its simulated time after every frame.
    pub progress: Progress,
    /// Set (e.g. by a Ctrl-C handler) to stop inside the current substep; the summary then
    /// covers the time simulated so far.
    pub stop: Option<Arc<AtomicBool>>,
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
    /// True when the run was stopped before its end (Ctrl-C).
    pub stopped_early: bool,
    /// SHA-256 of the final state's bits ([`Simulation::state_digest`]): equal digests, equal
    /// runs. None for a run stopped early (its state is not a result, and hashing millions of
    /// particles would hold up the stop for a second).
    pub state_digest: Option<String>,
}

/// Something that looks at the simulation at every frame (and at time 0), e.g. a bag recorder.
pub trait Observer {
    /// Called after each frame; an error stops the run.
    fn observe(&mut self, sim: &mut Simulation) -> Result<(), ObserverError>;
}

/// Observes nothing.
pub struct NoObserver;

impl Observer for NoObserver {
    fn observe(&mut self, _: &mut Simulation) -> Result<(), ObserverError> {
        Ok(())
    }
}

/// Runs a scene to its end and measures it.
pub fn run_scene(scene: &Scene, opts: &RunOptions) -> Result<RunSummary, RunError> {
    run_scene_observed(scene, opts, &mut NoObserver)
}

/// Runs a scene to its end (or until `opts.stop` is set), calling `observer` at time 0 and after
/// every frame, and measures it.
pub fn run_scene_observed(
    scene: &Scene,
    opts: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<RunSummary, RunError> {
    run_simulation_observed(scene, build_simulation(scene, opts)?, opts, observer)
}

/// The scene's simulation at time 0, its build stopped by `opts.stop` and its substeps polling
/// it.
pub fn build_simulation(scene: &Scene, opts: &RunOptions) -> Result<Simulation, RunError> {
    match &opts.stop {
        Some(stop) => Simulation::new_unless(scene, stop),
        None => Simulation::new(scene),
    }
}

/// [`run_scene_observed`] for the scene's simulation already built ([`build_simulation`]).
pub fn run_simulation_observed(
    scene: &Scene,
    mut sim: Simulation,
    opts: &RunOptions,
    observer: &mut dyn Observer,
) -> Result<RunSummary, RunError> {
    let config = &scene.config;
    for line in sim.bed_shortfalls() {
        eprintln!("warning: {}: sand bed: {line}", scene.file.display());
    }
    let duration = opts.duration_s.unwrap_or(config.duration_s);
    let frame_interval = config.output.frame_interval_s;
    let frames = (duration / frame_interval).ceil().max(1.0) as u64;
    let collapse = collapse_geometry(scene);
    let initial = sim
        .solver()
        .zip(collapse)
        .map(|(solver, g)| collapse::measure(&g, &solver.particles.position));

    let out_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&config.name));
    let ply_every = config.output.ply_every_frames as u64;
    let snapshots = ply_every > 0 && sim.solver().is_some();
    if snapshots {
        std::fs::create_dir_all(&out_dir).map_err(|source| RunError::Write {
            path: out_dir.clone(),
            source,
        })?;
        write_snapshot(&out_dir, 0, &sim)?;
    }
    let observe = |sim: &mut Simulation, observer: &mut dyn Observer| {
        observer.observe(sim).map_err(|error| RunError::Observer {
            time_s: sim.time_s(),
            error,
        })
    };
    observe(&mut sim, observer)?;

    let progress = &opts.progress;
    progress.start_run(&config.name, Some(duration));
    let wall = Instant::now();
    let (mut sinkage_sum, mut frames_done) = (0.0f64, 0u64);
    let mut stopped_early = false;
    for frame in 1..=frames {
        if opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
        {
            stopped_early = true;
            break;
        }
        let target = (frame as f64 * frame_interval).min(duration);
        progress.abandon_on_error(sim.advance_to(target))?;
        frames_done += 1;
        sinkage_sum += sim.leg_sinkage_m().unwrap_or(0.0);
        progress.advance(target, || match sim.solver() {
            Some(solver) => format!("step {} dt {:.2e} s", solver.steps, solver.next_dt()),
            None => format!("step {}", sim.steps()),
        });
        if snapshots && frame % ply_every == 0 {
            write_snapshot(&out_dir, frame, &sim)?;
        }
        progress.abandon_on_error(observe(&mut sim, observer))?;
    }
    progress.done();
    let wall_time_s = wall.elapsed().as_secs_f64();

    let mut metrics = Map::new();
    if let Some(robot) = sim.robot() {
        metrics = robot_metrics_json(robot);
    }
    if let Some(solver) = sim.solver() {
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
        if let Some(robot) = sim.robot() {
            metrics.insert(
                "mean_sinkage_m".into(),
                json!(sinkage_sum / frames_done.max(1) as f64),
            );
            metrics.insert("sand_mass_kg".into(), json!(solver.particles.total_mass()));
            metrics.insert("robot_mass_kg".into(), json!(robot.total_mass_kg()));
            metrics.insert("dx_m".into(), json!(solver.grid().dx));
            metrics.insert("bed_shortfalls".into(), json!(sim.bed_shortfalls()));
            metrics.insert("bed_edge".into(), json!(sim.bed_edge()));
            if let Some(edge) = sim.bed_edge() {
                eprintln!(
                    "warning: {}: the robot reached the sand bed's {} at t = {:.2} s: from \
                     then on it was at or over the bed's edge, not on open sand (a wider or \
                     longer bed: docs/scenes.md, \"How big a bed\")",
                    scene.file.display(),
                    edge.sides.join(" and "),
                    edge.time_s
                );
            }
            if let Some(window) = sim.sand_window() {
                metrics.insert("sand_window_m".into(), json!(window.x_m));
                metrics.insert("sand_added".into(), json!(window.added));
                metrics.insert("sand_dropped".into(), json!(window.dropped));
            }
        } else {
            metrics.insert("total_mass_kg".into(), json!(solver.particles.total_mass()));
        }
        if solver.settings.sleep.is_some() {
            let mean_awake = solver.awake_particle_steps as f64 / solver.steps.max(1) as f64;
            metrics.insert("mean_awake_particles".into(), json!(mean_awake));
            metrics.insert("blocks_woken".into(), json!(solver.sleep_changes.woken));
            metrics.insert(
                "blocks_fell_asleep".into(),
                json!(solver.sleep_changes.fell_asleep),
            );
        }
    }
    if let (Some(robot), Some(terrain)) = (sim.robot(), sim.rft_terrain()) {
        metrics.insert(
            "mean_sinkage_m".into(),
            json!(sinkage_sum / frames_done.max(1) as f64),
        );
        metrics.insert("robot_mass_kg".into(), json!(robot.total_mass_kg()));
        metrics.insert("zeta_n_m3".into(), json!(terrain.params().law.zeta_n_m3()));
    }
    Ok(RunSummary::of_simulation(
        &config.name,
        &sim,
        wall_time_s,
        metrics,
        stopped_early,
    ))
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
        lattice: Lattice::of(cc.particles_per_cell).expect("validated"),
    })
}

fn write_snapshot(dir: &std::path::Path, frame: u64, sim: &Simulation) -> Result<(), RunError> {
    let Some(solver) = sim.solver() else {
        return Ok(());
    };
    let path = dir.join(format!("particles_{frame:05}.ply"));
    super::ply::write_ply(&path, &solver.particles)
        .map_err(|source| RunError::Write { path, source })
}

impl RunSummary {
    /// The summary of a run of `sim` that took `wall_time_s` seconds.
    fn of_simulation(
        scene: &str,
        sim: &Simulation,
        wall_time_s: f64,
        metrics: Map<String, Value>,
        stopped_early: bool,
    ) -> Self {
        let time_s = sim.time_s();
        let stage_times_s = sim
            .solver()
            .map(|solver| {
                solver
                    .stage_times
                    .named()
                    .iter()
                    .map(|(name, t)| (name.to_string(), json!(t.as_secs_f64())))
                    .collect()
            })
            .unwrap_or_default();
        RunSummary {
            scene: scene.to_string(),
            steps: sim.steps(),
            sim_time_s: time_s,
            wall_time_s,
            particles: sim.solver().map_or(0, |s| s.particles.len()),
            particle_steps_per_s: sim.particle_steps() as f64 / wall_time_s.max(1e-9),
            wall_time_per_sim_s: wall_time_s / time_s.max(1e-12),
            stage_times_s,
            metrics,
            stopped_early,
            state_digest: (!stopped_early).then(|| sim.state_digest()),
        }
    }
}

/// The robot's metrics as a JSON map.
fn robot_metrics_json(robot: &RobotSim) -> Map<String, Value> {
    match serde_json::to_value(robot.metrics()).expect("plain data") {
        Value::Object(map) => map,
        _ => unreachable!("metrics serialise as a map"),
    }
}
