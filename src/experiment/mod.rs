//! `sandstep experiment`: robot speed against leg curvature and gait frequency on each terrain
//! model (Li, Zhang and Goldman 2013; Hu et al. 2018, supplement section 4), `docs/experiment.md`.
//!
//! For each curvature the hexapod's URDF is generated at the same total mass; each run is the
//! base scene with that URDF, frequency, terrain model and start, run and recorded like
//! `sandstep run` ([`crate::ros::record_run`]); its bag is analysed after settling
//! ([`crate::analysis::bag::analyze_bag_with`]). Results go to `results.csv` (a row per run),
//! `summary.csv` (a row per curvature, frequency and model, pooling the starts), `results.json`
//! and a chart; a failed run is recorded and the others go on. Every run also leaves a record
//! of its own in `runs/`, so the runs can be spread over a cluster's jobs and merged
//! ([`crate::shard`], [`merge_experiment`]).

pub mod charts;
pub mod config;
pub mod results;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use charts::{write_speed_chart, SPEED_CHART};
pub use config::{
    model_override, start_override, Experiment, ExperimentConfig, GaitWindow, RunSpec,
    TerrainModel, LEAD_CYCLES, WINDOW_EXTRA_CYCLES,
};
pub use results::{
    results_csv, summarize, summary_csv, write_results_csv, CellSummary, RunResult, CSV_COLUMNS,
    STATUS_OK, SUMMARY_COLUMNS, TURNED_OVER_TILT_DEG,
};

use crate::analysis::bag::{analyze_bag_with, AnalysisOptions};
use crate::analysis::plots::PlotError;
use crate::progress::Progress;
use crate::robot::RobotMetrics;
use crate::scene::{Observer, RunOptions, Scene, SceneError, Simulation};
use crate::shard::{local_time_now, MergeError, Selection, UnitRecord};

/// Parent of the default output folders.
pub const DEFAULT_OUT_PARENT: &str = "out/experiments";
/// The results table.
pub const RESULTS_CSV: &str = "results.csv";
/// The results with the experiment's settings.
pub const RESULTS_JSON: &str = "results.json";
/// One row per cell of the sweep (model, frequency, curvature) over its starts.
pub const SUMMARY_CSV: &str = "summary.csv";
/// The generated robot of each curvature: `<out>/urdf/k<curvature>/hexapod.urdf`.
pub const URDF_DIR: &str = "urdf";
/// Each run's bag: `<out>/bags/<run name>/`.
pub const BAGS_DIR: &str = "bags";
/// Each run's record: `<out>/runs/<run name>.json` ([`RunRecord`]).
pub const RUNS_DIR: &str = "runs";
/// Largest difference between a run's simulated robot mass and `robot_total_mass_kg` (kg):
/// rapier keeps masses in f32.
pub const MASS_TOLERANCE_KG: f64 = 1e-6;

/// Why an experiment could not be run at all (a failing run is not an error: it is recorded).
#[derive(thiserror::Error, Debug)]
pub enum ExperimentError {
    #[error(transparent)]
    Config(#[from] crate::config_error::ConfigError),
    #[error("generating the robot with curvature {curvature_per_r}")]
    Urdf {
        curvature_per_r: f64,
        source: crate::robot::RobotError,
    },
    #[error("drawing the chart: {0}")]
    Plot(#[from] PlotError),
    #[error("cannot resume from {}: {message}", path.display())]
    Resume { path: PathBuf, message: String },
    #[error(transparent)]
    Select(#[from] crate::shard::UnknownRun),
    #[error(
        "{} holds the bag of an earlier attempt at run {run}: --resume keeps the runs it \
         finished and runs the rest; or choose another --out",
        bag.display()
    )]
    AlreadyRun { run: String, bag: PathBuf },
    #[error(transparent)]
    Records(#[from] MergeError),
}

/// The status of a run not started because the experiment was stopped.
const STOPPED_BEFORE_START: &str = "not run: the experiment was stopped";

/// What a run leaves in `runs/` for a merge.
pub type RunRecord = UnitRecord<ExperimentConfig, RunResult>;

/// How to run an experiment.
#[derive(Clone, Debug, Default)]
pub struct ExperimentOptions {
    /// Output folder; default `out/experiments/<name>-<YYYYmmdd-HHMMSS>` ([`default_out_dir`]).
    pub out_dir: Option<PathBuf>,
    /// Where the experiment reports its runs and the current run's simulated time.
    pub progress: Progress,
    /// Set (e.g. by a Ctrl-C handler) to stop the current run after its frame and skip the
    /// rest; everything so far is written.
    pub stop: Option<Arc<AtomicBool>>,
    /// Continue the experiment in `out_dir` (which must be given): runs whose `results.json`
    /// status there is `ok` and whose bag is present are kept, the others are run again
    /// (their partial bags replaced). The experiment's settings must equal those recorded.
    /// With a [`Selection`] other than all, the runs' records in `runs/` say what is kept.
    pub resume: bool,
    /// The runs to run: all (and the experiment's results written), or a shard or named runs
    /// (only their records written, for [`merge_experiment`]).
    pub select: Selection,
}

/// What an experiment did: `results.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ExperimentReport {
    /// The experiment's name.
    pub experiment: String,
    /// The experiment file.
    pub file: String,
    /// Its settings, defaults filled in.
    pub config: ExperimentConfig,
    /// Start of the measurement at each frequency (s), in `config.frequencies_hz` order: a
    /// quarter cycle before the first cycle boundary at or after `settle_s`.
    pub measure_from_s: Vec<f64>,
    /// Simulated time of a run at each frequency (s), in `config.frequencies_hz` order.
    pub run_duration_s: Vec<f64>,
    /// The output folder.
    pub out_dir: String,
    /// Local start time, `YYYY-mm-dd HH:MM:SS`.
    pub started: String,
    /// Worker threads of the simulations.
    pub threads: usize,
    /// One per run, in the order run.
    pub runs: Vec<RunResult>,
    /// One per cell of the sweep (model, frequency, curvature) over its starts: `summary.csv`.
    #[serde(default)]
    pub cells: Vec<CellSummary>,
    /// Runs whose status is not `ok`.
    pub failed: usize,
    /// Wall time of the whole experiment (s).
    pub wall_time_s: f64,
    /// Files written besides the bags and URDFs: results and charts.
    pub files: Vec<String>,
}

/// `out/experiments/<name>-<YYYYmmdd-HHMMSS>`, with `-2`, `-3`, ... if taken.
pub fn default_out_dir(name: &str) -> PathBuf {
    crate::ros::default_bag_dir(Path::new(DEFAULT_OUT_PARENT), name)
}

/// The record of run `name` under `out`: `runs/<name>.json`.
pub fn record_path(out: &Path, name: &str) -> PathBuf {
    out.join(RUNS_DIR).join(format!("{name}.json"))
}

/// The folder of the robot with legs of `curvature_per_r` under `out`: `urdf/k<curvature>`.
pub fn urdf_path(out: &Path, curvature_per_r: f64) -> PathBuf {
    out.join(URDF_DIR)
        .join(format!("k{}", config::number(curvature_per_r)))
        .join("hexapod.urdf")
}

/// Runs the selected runs of `experiment` ([`ExperimentOptions::select`]), writing URDFs,
/// bags and each run's record (`runs/<name>.json`) into the output folder. With every run
/// selected it also writes `results.csv`, `summary.csv`, `results.json` (after every run, so a
/// crash keeps what was done) and the chart; a shard leaves those to [`merge_experiment`].
pub fn run_experiment(
    experiment: &Experiment,
    opts: &ExperimentOptions,
) -> Result<ExperimentReport, ExperimentError> {
    let cfg = &experiment.config;
    let out = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| default_out_dir(&cfg.name));
    let all_runs = experiment.runs();
    let names: Vec<&str> = all_runs.iter().map(|r| r.name.as_str()).collect();
    let picked = opts.select.pick(&names)?;
    let runs: Vec<&RunSpec> = all_runs
        .iter()
        .zip(picked)
        .filter_map(|(run, picked)| picked.then_some(run))
        .collect();
    if !opts.resume {
        // Bags are never overwritten: refuse before running anything, not run by run.
        for spec in &runs {
            let bag = out.join(BAGS_DIR).join(&spec.name);
            if std::fs::read_dir(&bag).is_ok_and(|mut entries| entries.next().is_some()) {
                return Err(ExperimentError::AlreadyRun {
                    run: spec.name.clone(),
                    bag,
                });
            }
        }
    }
    let mut kept = if opts.resume {
        resumable_runs(&out, cfg, &runs, opts.select.is_all())?
    } else {
        Vec::new()
    };
    std::fs::create_dir_all(&out).map_err(write_error(&out))?;
    // The robots of the runs to run (shards in one folder write the same bytes: kept as is).
    for &k in &cfg.curvatures_per_r {
        if !runs.iter().any(|r| r.curvature_per_r == k) {
            continue;
        }
        let urdf = urdf_path(&out, k);
        crate::robot::write_hexapod_urdf(&experiment.robot_params(k), &urdf).map_err(|source| {
            ExperimentError::Urdf {
                curvature_per_r: k,
                source,
            }
        })?;
    }
    let threads = rayon::current_num_threads();
    let mut report = blank_report(experiment, &out, local_time_now(), threads);

    let durations_s: Vec<f64> = runs.iter().map(|r| r.duration_s).collect();
    let progress = &opts.progress;
    progress.plan(&durations_s);
    let wall = Instant::now();
    let stopped = || {
        opts.stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed))
    };
    for spec in runs {
        let previous = kept.iter().position(|r| r.result.run == spec.name);
        let record = if let Some(i) = previous {
            progress.skip_run(
                spec.duration_s,
                &format!("{}: kept from the earlier attempt", spec.name),
            );
            kept.swap_remove(i)
        } else {
            let started = local_time_now();
            let result = if stopped() {
                not_run(spec, STOPPED_BEFORE_START)
            } else {
                let bag = out.join(BAGS_DIR).join(&spec.name);
                if opts.resume && bag.exists() {
                    // A failed or interrupted run of the earlier attempt: run it again.
                    std::fs::remove_dir_all(&bag).map_err(write_error(&bag))?;
                }
                progress.start_run(&spec.name, Some(spec.duration_s));
                let result = run_one(experiment, spec, &out, opts);
                progress.finish_run(spec.duration_s, &finish_line(spec, &result));
                result
            };
            RunRecord {
                config: cfg.clone(),
                started,
                threads,
                result,
            }
        };
        let record_file = record_path(&out, &spec.name);
        if record.result.is_ok() || !stopped() {
            // A run stopped (or never started) by a signal leaves no record: a merge names it
            // as missing, and a resume runs it.
            crate::shard::write_record(&record_file, &record).map_err(write_error(&record_file))?;
        }
        report.failed += usize::from(!record.result.is_ok());
        report.runs.push(record.result);
        report.wall_time_s = wall.elapsed().as_secs_f64();
        if opts.select.is_all() {
            write_tables(&mut report, &out)?;
        } else {
            report.files.push(record_file.display().to_string());
        }
    }
    progress.done();

    report.cells = summarize(&report.runs);
    if opts.select.is_all() {
        write_final(&mut report, &out)?;
    }
    Ok(report)
}

/// Merges the records that the shards of `experiment` left in `out` (`runs/`) into the
/// experiment's results, as [`run_experiment`] writes them for all its runs in one process;
/// an error names the runs without a record. The report's wall time is the sum of the runs'.
pub fn merge_experiment(
    experiment: &Experiment,
    out: &Path,
) -> Result<ExperimentReport, ExperimentError> {
    let units: Vec<(String, PathBuf)> = experiment
        .runs()
        .into_iter()
        .map(|r| {
            let path = record_path(out, &r.name);
            (r.name, path)
        })
        .collect();
    let records: Vec<RunRecord> =
        crate::shard::read_all_records(out, "runs", &units, &experiment.config)?;
    let started = crate::shard::earliest_start(&records);
    let threads = crate::shard::most_threads(&records);
    let mut report = blank_report(experiment, out, started, threads);
    report.runs = records.into_iter().map(|r| r.result).collect();
    report.failed = report.runs.iter().filter(|r| !r.is_ok()).count();
    report.wall_time_s = report.runs.iter().filter_map(|r| r.wall_time_s).sum();
    report.cells = summarize(&report.runs);
    write_final(&mut report, out)?;
    Ok(report)
}

/// An error writing `path`.
fn write_error(path: &Path) -> impl FnOnce(std::io::Error) -> ExperimentError {
    let path = path.to_path_buf();
    move |source| ExperimentError::from(crate::config_error::ConfigError::write(&path, source))
}

/// The report of `experiment` in `out` before any run.
fn blank_report(
    experiment: &Experiment,
    out: &Path,
    started: String,
    threads: usize,
) -> ExperimentReport {
    let cfg = &experiment.config;
    let per_frequency = |f: fn(&Experiment, f64) -> f64| {
        cfg.frequencies_hz
            .iter()
            .map(|&hz| f(experiment, hz))
            .collect()
    };
    ExperimentReport {
        experiment: cfg.name.clone(),
        file: experiment.file.display().to_string(),
        config: cfg.clone(),
        measure_from_s: per_frequency(Experiment::measure_from_s),
        run_duration_s: per_frequency(Experiment::run_duration_s),
        out_dir: out.display().to_string(),
        started,
        threads,
        runs: Vec::new(),
        cells: Vec::new(),
        failed: 0,
        wall_time_s: 0.0,
        files: Vec::new(),
    }
}

/// Writes `results.csv`, `summary.csv` (summarising the runs) and `results.json`.
fn write_tables(report: &mut ExperimentReport, out: &Path) -> Result<(), ExperimentError> {
    let csv_path = out.join(RESULTS_CSV);
    write_results_csv(&csv_path, &report.runs).map_err(write_error(&csv_path))?;
    report.cells = summarize(&report.runs);
    let summary_path = out.join(SUMMARY_CSV);
    std::fs::write(&summary_path, summary_csv(&report.cells))
        .map_err(write_error(&summary_path))?;
    let json_path = out.join(RESULTS_JSON);
    let json = serde_json::to_string_pretty(report).expect("plain data");
    std::fs::write(&json_path, json + "\n").map_err(write_error(&json_path))
}

/// Draws the chart, lists the files and writes the tables a last time.
fn write_final(report: &mut ExperimentReport, out: &Path) -> Result<(), ExperimentError> {
    let cfg = &report.config;
    let charts = write_speed_chart(&report.runs, &cfg.terrain_models, &cfg.frequencies_hz, out)?;
    report.files = [RESULTS_CSV, SUMMARY_CSV, RESULTS_JSON]
        .iter()
        .map(|name| out.join(name))
        .chain(charts)
        .map(|p| p.display().to_string())
        .collect();
    write_tables(report, out)
}

/// The runs of an earlier attempt recorded in `json_path` that went through and whose bag is
/// still there; an error if the file is missing or holds a different experiment.
fn finished_runs(
    json_path: &Path,
    cfg: &ExperimentConfig,
) -> Result<Vec<RunRecord>, ExperimentError> {
    let fail = |message: String| ExperimentError::Resume {
        path: json_path.to_path_buf(),
        message,
    };
    let text = std::fs::read_to_string(json_path).map_err(|e| fail(e.to_string()))?;
    let earlier: ExperimentReport = serde_json::from_str(&text)
        .map_err(|e| fail(format!("not an experiment's results: {e}")))?;
    if earlier.config != *cfg {
        return Err(fail(format!(
            "it holds a different experiment (recorded settings {}; now {})",
            serde_json::to_string(&earlier.config).expect("plain data"),
            serde_json::to_string(cfg).expect("plain data")
        )));
    }
    Ok(earlier
        .runs
        .into_iter()
        .filter(has_finished)
        .map(|result| RunRecord {
            config: earlier.config.clone(),
            started: earlier.started.clone(),
            threads: earlier.threads,
            result,
        })
        .collect())
}

/// The runs among `runs` that an earlier attempt in `out` finished, whose bag is still there:
/// from their records in `runs/`, and for runs without one from `results.json` (older
/// builds wrote no records). An error if either holds a different experiment, or, with
/// `all` runs selected, if there is neither.
fn resumable_runs(
    out: &Path,
    cfg: &ExperimentConfig,
    runs: &[&RunSpec],
    all: bool,
) -> Result<Vec<RunRecord>, ExperimentError> {
    let mut kept = Vec::new();
    let mut recorded = Vec::new();
    for spec in runs {
        let path = record_path(out, &spec.name);
        let record: Option<RunRecord> = crate::shard::read_record(&path, cfg)?;
        if let Some(record) = record {
            recorded.push(spec.name.as_str());
            kept.extend(has_finished(&record.result).then_some(record));
        }
    }
    let json_path = out.join(RESULTS_JSON);
    if json_path.exists() || (all && recorded.is_empty()) {
        let wanted = |name: &str| runs.iter().any(|r| r.name == name) && !recorded.contains(&name);
        kept.extend(
            finished_runs(&json_path, cfg)?
                .into_iter()
                .filter(|r| wanted(&r.result.run)),
        );
    }
    Ok(kept)
}

/// Whether a run went through and its bag is still there.
fn has_finished(result: &RunResult) -> bool {
    result.is_ok() && Path::new(&result.bag).join("metadata.yaml").is_file()
}

/// A row for a run that did not go through.
fn not_run(spec: &RunSpec, status: impl Into<String>) -> RunResult {
    RunResult {
        run: spec.name.clone(),
        curvature_per_r: spec.curvature_per_r,
        frequency_hz: spec.frequency_hz,
        terrain_model: spec.terrain_model.name().into(),
        start_x_m: spec.start_x_m,
        status: status.into(),
        ..RunResult::default()
    }
}

/// `value` as a YAML scalar for `--set` (quoted where YAML needs it).
fn yaml_scalar(value: &str) -> String {
    serde_yaml_ng::to_string(value)
        .map(|s| s.trim_end().to_string())
        .unwrap_or_else(|_| value.to_string())
}

/// The base scene with the run's URDF, frequency, terrain model and start.
fn run_scene(experiment: &Experiment, spec: &RunSpec, urdf: &Path) -> Result<Scene, SceneError> {
    let cfg = &experiment.config;
    let mut overrides = cfg.overrides.clone();
    overrides.extend([
        format!("robot.urdf={}", yaml_scalar(&urdf.display().to_string())),
        format!("robot.gait.frequency_hz={}", spec.frequency_hz),
        model_override(spec.terrain_model),
        start_override(spec.start_x_m),
    ]);
    Scene::load(&cfg.base_scene, &overrides)
}

/// Follows a run: the progress bar, the robot's mass, its latest metrics and when it reached
/// the sand bed's side.
struct RunWatch<'a> {
    progress: &'a Progress,
    robot_mass_kg: Option<f64>,
    metrics: Option<RobotMetrics>,
    particles: usize,
    bed_edge_s: Option<f64>,
}

impl Observer for RunWatch<'_> {
    fn observe(&mut self, sim: &mut Simulation) -> Result<(), crate::scene::ObserverError> {
        self.progress.advance(sim.time_s(), String::new);
        if let Some(robot) = sim.robot() {
            if self.robot_mass_kg.is_none() {
                self.robot_mass_kg = Some(robot.total_mass_kg());
            }
            self.metrics = Some(robot.metrics());
        }
        self.particles = sim.solver().map_or(0, |s| s.particles.len());
        self.bed_edge_s = sim.bed_edge().map(|edge| edge.time_s);
        Ok(())
    }
}

/// Runs, records and measures one run; failures become its status.
fn run_one(
    experiment: &Experiment,
    spec: &RunSpec,
    out: &Path,
    opts: &ExperimentOptions,
) -> RunResult {
    let cfg = &experiment.config;
    let urdf = urdf_path(out, spec.curvature_per_r);
    let bag_dir = out.join(BAGS_DIR).join(&spec.name);
    let mut result = RunResult {
        urdf: urdf.display().to_string(),
        bag: bag_dir.display().to_string(),
        ..not_run(spec, STATUS_OK)
    };
    let scene = match run_scene(experiment, spec, &urdf) {
        Ok(scene) => scene,
        Err(e) => {
            result.status = e.to_string();
            return result;
        }
    };
    let run_opts = RunOptions {
        duration_s: Some(spec.duration_s),
        out_dir: Some(out.join("ply").join(&spec.name)),
        progress: Progress::none(),
        stop: opts.stop.clone(),
    };
    let mut watch = RunWatch {
        progress: &opts.progress,
        robot_mass_kg: None,
        metrics: None,
        particles: 0,
        bed_edge_s: None,
    };
    let recorded = crate::ros::record_run(&scene, &run_opts, Some(&bag_dir), &mut watch);
    result.robot_mass_kg = watch.robot_mass_kg;
    result.particles = Some(watch.particles);
    result.bed_edge_s = watch.bed_edge_s;
    if let Some(m) = watch.metrics {
        result.max_tilt_deg = Some(m.max_tilt_deg);
        result.final_position_m = Some(m.final_position_m);
        result.yaw_change_deg = Some(m.yaw_change_deg);
        result.travel_direction_deg = Some(m.travel_direction_deg);
    }
    let run = match recorded {
        Ok(run) => run,
        Err(e) => {
            result.status = e.to_string();
            return result;
        }
    };
    result.sim_time_s = Some(run.summary.sim_time_s);
    result.wall_time_s = Some(run.summary.wall_time_s);
    result.wall_time_per_sim_s = Some(run.summary.wall_time_per_sim_s);
    if run.summary.stopped_early {
        result.status = format!(
            "stopped at t = {:.3} s of {} s",
            run.summary.sim_time_s, spec.duration_s
        );
        return result;
    }
    if let Some(mass) = result.robot_mass_kg {
        if (mass - cfg.robot_total_mass_kg).abs() > MASS_TOLERANCE_KG {
            result.status = format!(
                "the simulated robot weighs {mass} kg, not robot_total_mass_kg = {} kg",
                cfg.robot_total_mass_kg
            );
            return result;
        }
    }
    let analysis_opts = AnalysisOptions {
        start_s: spec.measure_from_s,
        max_cycles: Some(cfg.cycles as usize),
    };
    let analysis = match analyze_bag_with(&bag_dir, &analysis_opts) {
        Ok(a) => a.summary,
        Err(e) => {
            result.status = format!("analysing the bag: {e}");
            return result;
        }
    };
    result.mean_speed_m_s = analysis.mean_speed_m_s;
    result.speed_per_cycle_mean_m_s = analysis.speed_per_cycle_mean_m_s;
    result.speed_per_cycle_std_m_s = analysis.speed_per_cycle_std_m_s;
    result.speed_per_cycle_m_s = analysis.speed_per_cycle_m_s;
    result.cycles = analysis.gait_cycles;
    result.sinkage_mean_m = analysis.sinkage_mean_m;
    result
}

/// The line printed when a run is over.
fn finish_line(spec: &RunSpec, result: &RunResult) -> String {
    if result.is_ok() {
        format!(
            "{}: {} m/s per cycle (std {}), tilt {} deg, {:.0} s wall",
            spec.name,
            fmt_opt(result.speed_per_cycle_mean_m_s, 4),
            fmt_opt(result.speed_per_cycle_std_m_s, 4),
            fmt_opt(result.max_tilt_deg, 0),
            result.wall_time_s.unwrap_or(0.0)
        )
    } else {
        format!("{} failed: {}", spec.name, result.status)
    }
}

/// `v` with `decimals`, or `-`.
fn fmt_opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.decimals$}"))
}

/// The human summary of a report: one line per run.
pub fn report_table(report: &ExperimentReport) -> String {
    let mut text = format!(
        "{}: {} runs, {} failed, {:.0} s wall; results in {}\n",
        report.experiment,
        report.runs.len(),
        report.failed,
        report.wall_time_s,
        report.out_dir
    );
    text.push_str(&format!(
        "{:>6} {:>5} {:>4} {:>8} {:>9} {:>17} {:>6} {:>8} {:>9} {:>6} {:>6} {:>6} {:>7}  status\n",
        "k(1/R)",
        "f Hz",
        "model",
        "start mm",
        "mean m/s",
        "per cycle m/s",
        "cycles",
        "sink mm",
        "mass g",
        "tilt",
        "dir",
        "edge s",
        "wall/s"
    ));
    for r in &report.runs {
        let per_cycle = match (r.speed_per_cycle_mean_m_s, r.speed_per_cycle_std_m_s) {
            (Some(m), Some(s)) => format!("{m:.4} +- {s:.4}"),
            _ => "-".into(),
        };
        text.push_str(&format!(
            concat!(
                "{:>6} {:>5} {:>4} {:>8.1} {:>9} {:>17} {:>6} {:>8} {:>9} ",
                "{:>6} {:>6} {:>6} {:>7}  {}\n"
            ),
            config::number(r.curvature_per_r),
            config::number(r.frequency_hz),
            r.terrain_model,
            r.start_x_m * 1e3,
            fmt_opt(r.mean_speed_m_s, 4),
            per_cycle,
            r.cycles.map_or("-".into(), |n| n.to_string()),
            fmt_opt(r.sinkage_mean_m.map(|s| s * 1e3), 1),
            fmt_opt(r.robot_mass_kg.map(|m| m * 1e3), 3),
            fmt_opt(r.max_tilt_deg, 0),
            fmt_opt(r.travel_direction_deg, 0),
            fmt_opt(r.bed_edge_s, 2),
            r.wall_time_per_sim_s
                .map_or("-".into(), |w| format!("{w:.2}")),
            r.status
        ));
    }
    if report.cells.iter().any(|c| c.starts > 1) {
        text.push_str(&format!(
            "\nover starts ({}):\n{:>6} {:>5} {:>4} {:>11} {:>26} {:>8} {:>8} {:>9} {:>6} {:>6}\n",
            SUMMARY_CSV,
            "k(1/R)",
            "f Hz",
            "model",
            "completed",
            "speed m/s (std, std err)",
            "sink mm",
            "max tilt",
            "max |dir|",
            "over",
            "edge"
        ));
        for c in &report.cells {
            let speed = match (
                c.speed_mean_m_s,
                c.speed_std_m_s,
                c.speed_standard_error_m_s,
            ) {
                (Some(m), Some(s), Some(e)) => format!("{m:.4} ({s:.4}, {e:.4})"),
                (Some(m), ..) => format!("{m:.4}"),
                _ => "-".into(),
            };
            text.push_str(&format!(
                "{:>6} {:>5} {:>4} {:>11} {:>26} {:>8} {:>8} {:>9} {:>6} {:>6}\n",
                config::number(c.curvature_per_r),
                config::number(c.frequency_hz),
                c.terrain_model,
                format!("{} of {}", c.completed, c.starts),
                speed,
                fmt_opt(c.sinkage_mean_m.map(|s| s * 1e3), 1),
                fmt_opt(c.max_tilt_deg, 0),
                fmt_opt(c.max_abs_travel_direction_deg, 0),
                c.turned_over,
                c.reached_bed_edge
            ));
        }
    }
    text
}
