//! `sandstep sweep`: what each setting costs and what it buys (`docs/speed-vs-accuracy.md`).
//!
//! A sweep file lists studies: a base scene, a quantity of interest (the robot's mean speed,
//! or the column collapse's runout) and settings (grid spacing, particles per cell, CFL number,
//! Young's modulus, terrain model...). Each setting is run headless
//! ([`crate::scene::run_scene_observed`]); its cost is the wall time per simulated second, its
//! error the quantity's relative error against the study's reference run or the published law.
//! Results go to `results.csv` and `results.json` (after every run, so a crash keeps what was
//! done) and a chart per study of error against cost with the Pareto front marked. A setting
//! that fails (e.g. blows up) is recorded and the others go on. Every setting also leaves a
//! record of its own in `settings/`, so the settings can be spread over a cluster's jobs and
//! merged ([`crate::shard`], [`merge_sweep`]).

pub mod chart;
pub mod config;
pub mod pareto;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use serde::{Deserialize, Serialize};

pub use config::{Quantity, Setting, Sweep, SweepConfig};

use crate::analysis::bag::mean_and_sample_std;
use crate::analysis::plots::PlotError;
use crate::experiment::config::GaitWindow;
use crate::experiment::results::csv_table;
use crate::progress::Progress;
use crate::scene::{run_scene_observed, Observer, RunOptions, Simulation};
use crate::shard::{local_time_now, MergeError, Selection, UnitRecord};

/// Parent of the default output folders.
pub const DEFAULT_OUT_PARENT: &str = "out/sweeps";
/// The results table.
pub const RESULTS_CSV: &str = "results.csv";
/// The results with the sweep's settings.
pub const RESULTS_JSON: &str = "results.json";
/// Each setting's record: `<out>/settings/<study>/<n>.json` ([`Sweep::record_path`]).
pub const SETTINGS_DIR: &str = "settings";
/// `status` of a setting that went through.
pub const STATUS_OK: &str = "ok";
/// Times within this much (s) of the window's start count as reaching it (frame times are
/// sums of frame intervals).
const WINDOW_TIME_TOLERANCE_S: f64 = 1e-9;

/// The columns of `results.csv`, in order (`docs/speed-vs-accuracy.md`).
pub const CSV_COLUMNS: [&str; 17] = [
    "study",
    "setting",
    "quantity",
    "value",
    "value_std",
    "starts",
    "reference_value",
    "relative_error",
    "relative_error_noise",
    "wall_time_per_sim_s",
    "wall_time_s",
    "sim_time_s",
    "particles",
    "substeps",
    "pareto_optimal",
    "status",
    "overrides",
];

/// Why a sweep could not be run at all (a failing setting is not an error: it is recorded).
#[derive(thiserror::Error, Debug)]
pub enum SweepError {
    #[error(transparent)]
    Config(#[from] crate::config_error::ConfigError),
    #[error("drawing a chart: {0}")]
    Plot(#[from] PlotError),
    #[error(transparent)]
    Select(#[from] crate::shard::UnknownRun),
    #[error(transparent)]
    Records(#[from] MergeError),
}

/// What a setting leaves in `settings/` for a merge.
pub type SettingRecord = UnitRecord<SweepConfig, SettingResult>;

/// How to run a sweep.
#[derive(Clone, Debug, Default)]
pub struct SweepOptions {
    /// Output folder; default `out/sweeps/<name>-<YYYYmmdd-HHMMSS>`.
    pub out_dir: Option<PathBuf>,
    /// Where the sweep reports its settings and the current run's simulated time.
    pub progress: Progress,
    /// Set (e.g. by a Ctrl-C handler) to stop the current run after its frame and skip the
    /// rest; everything so far is written.
    pub stop: Option<Arc<AtomicBool>>,
    /// The settings to run: all (and the sweep's results written), or a shard or named
    /// settings (only their records written, for [`merge_sweep`]).
    pub select: Selection,
}

/// What one setting cost and measured: a row of `results.csv`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SettingResult {
    /// The study's name.
    pub study: String,
    /// `reference`, `baseline`, `<axis name>=<value>` or a named setting.
    pub setting: String,
    /// `robot_speed` or `collapse_runout`.
    pub quantity: String,
    /// The measured quantity: mean speed along x (m/s) or normalized runout (-); the mean over
    /// the starts.
    pub value: Option<f64>,
    /// Standard deviation of the value over the starts (sample, N - 1); None for one start.
    pub value_std: Option<f64>,
    /// Runs made (starts of the robot), each measured.
    pub starts: usize,
    /// The value of each start, in start order (`results.json` only): pool starts across
    /// sweeps or settings when a few starts leave the noise unclear.
    #[serde(default)]
    pub start_values: Vec<f64>,
    /// What it is held against: the reference run's speed or the published runout.
    pub reference_value: Option<f64>,
    /// `|value - reference_value| / |reference_value|` (0 for the reference run itself).
    pub relative_error: Option<f64>,
    /// One standard error of `relative_error` from the spread over the starts (setting's and
    /// reference's): errors below about twice this are not resolved. None for one start.
    pub relative_error_noise: Option<f64>,
    /// Wall time per simulated second (s/s): the cost.
    pub wall_time_per_sim_s: Option<f64>,
    /// Wall time of the simulation (s).
    pub wall_time_s: Option<f64>,
    /// Simulated time (s).
    pub sim_time_s: Option<f64>,
    /// Sand particles (0 without MPM sand).
    pub particles: Option<usize>,
    /// Simulation steps (MPM substeps, or robot steps without sand).
    pub substeps: Option<u64>,
    /// On the study's Pareto front of (cost, error), the reference excluded.
    pub pareto_optimal: bool,
    /// `ok`, or why the run failed.
    pub status: String,
    /// The setting's changes to the base scene (the study's own overrides not repeated).
    pub overrides: Vec<String>,
    /// Whether this is the study's reference run.
    pub is_reference: bool,
    /// The run's scene-specific measurements (`sandstep run --json`'s `metrics`).
    pub metrics: serde_json::Map<String, serde_json::Value>,
}

impl SettingResult {
    /// Whether the run went through.
    pub fn is_ok(&self) -> bool {
        self.status == STATUS_OK
    }

    /// The CSV cells of this row, in [`CSV_COLUMNS`] order.
    fn csv_cells(&self) -> Vec<String> {
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
        vec![
            self.study.clone(),
            self.setting.clone(),
            self.quantity.clone(),
            opt(self.value),
            opt(self.value_std),
            self.starts.to_string(),
            opt(self.reference_value),
            opt(self.relative_error),
            opt(self.relative_error_noise),
            opt(self.wall_time_per_sim_s),
            opt(self.wall_time_s),
            opt(self.sim_time_s),
            self.particles.map_or(String::new(), |n| n.to_string()),
            self.substeps.map_or(String::new(), |n| n.to_string()),
            self.pareto_optimal.to_string(),
            self.status.clone(),
            self.overrides.join(" "),
        ]
    }
}

/// The text of `results.csv`.
pub fn results_csv(results: &[SettingResult]) -> String {
    csv_table(&CSV_COLUMNS, results.iter().map(SettingResult::csv_cells))
}

/// What a sweep did: `results.json`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SweepReport {
    /// The sweep's name.
    pub sweep: String,
    /// The sweep file.
    pub file: String,
    /// Its settings, defaults filled in.
    pub config: SweepConfig,
    /// The output folder.
    pub out_dir: String,
    /// Local start time, `YYYY-mm-dd HH:MM:SS`.
    pub started: String,
    /// Worker threads of the simulations.
    pub threads: usize,
    /// One per setting, in the order run.
    pub results: Vec<SettingResult>,
    /// Settings whose status is not `ok`.
    pub failed: usize,
    /// Wall time of the whole sweep (s).
    pub wall_time_s: f64,
    /// Files written: results and charts.
    pub files: Vec<String>,
}

/// `out/sweeps/<name>-<YYYYmmdd-HHMMSS>`, with `-2`, `-3`, ... if taken.
pub fn default_out_dir(name: &str) -> PathBuf {
    crate::ros::default_bag_dir(Path::new(DEFAULT_OUT_PARENT), name)
}

/// Fills in each row's reference value (the reference run's, for `robot_speed`), relative
/// error and Pareto flag, study by study.
pub fn score(results: &mut [SettingResult]) {
    let studies: Vec<String> = results.iter().map(|r| r.study.clone()).collect();
    for study in studies
        .iter()
        .enumerate()
        .filter(|(i, s)| !studies[..*i].contains(s))
        .map(|(_, s)| s)
    {
        let reference_row = results
            .iter()
            .find(|r| &r.study == study && r.is_reference && r.is_ok());
        let reference = reference_row.and_then(|r| r.value);
        let reference_sq_error = reference_row.and_then(standard_error).map(|e| e * e);
        let rows: Vec<usize> = (0..results.len())
            .filter(|&i| &results[i].study == study)
            .collect();
        for &i in &rows {
            let row = &mut results[i];
            if row.quantity == Quantity::RobotSpeed.name() {
                row.reference_value = reference;
            }
            row.relative_error = match (row.is_ok(), row.value, row.reference_value) {
                (true, Some(v), Some(r)) if r != 0.0 => Some((v - r).abs() / r.abs()),
                _ => None,
            };
            row.relative_error_noise = match (row.relative_error, reference, reference_sq_error) {
                (Some(_), Some(r), Some(r_sq)) if !row.is_reference => {
                    standard_error(row).map(|e| (e * e + r_sq).sqrt() / r.abs())
                }
                _ => None,
            };
        }
        let candidates: Vec<usize> = rows
            .into_iter()
            .filter(|&i| !results[i].is_reference)
            .collect();
        let points: Vec<(f64, f64)> = candidates
            .iter()
            .map(|&i| {
                let r = &results[i];
                (
                    r.wall_time_per_sim_s
                        .filter(|_| r.is_ok())
                        .unwrap_or(f64::NAN),
                    r.relative_error.unwrap_or(f64::NAN),
                )
            })
            .collect();
        for (&i, optimal) in candidates.iter().zip(pareto::pareto_optimal(&points)) {
            results[i].pareto_optimal = optimal;
        }
    }
}

/// The standard error of a row's mean value over its starts, if it has several.
fn standard_error(row: &SettingResult) -> Option<f64> {
    row.value_std.map(|s| s / (row.starts as f64).sqrt())
}

/// Runs the selected settings of `sweep` ([`SweepOptions::select`]), each leaving its record
/// (`settings/<study>/<n>.json`) in the output folder. With every setting selected it also
/// writes `results.csv`, `results.json` (after every run) and a chart per study; a shard
/// leaves those to [`merge_sweep`].
pub fn run_sweep(sweep: &Sweep, opts: &SweepOptions) -> Result<SweepReport, SweepError> {
    let cfg = &sweep.config;
    let out = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| default_out_dir(&cfg.name));
    std::fs::create_dir_all(&out).map_err(write_error(&out))?;
    let labels = sweep.labels();
    let names: Vec<&str> = labels.iter().map(String::as_str).collect();
    let picked = opts.select.pick(&names)?;
    let threads = rayon::current_num_threads();
    let mut report = blank_report(sweep, &out, local_time_now(), threads);

    let selected: Vec<usize> = (0..sweep.settings.len()).filter(|&i| picked[i]).collect();
    let durations_s: Vec<f64> = selected
        .iter()
        .map(|&i| sweep.settings[i].duration_s * sweep.settings[i].runs() as f64)
        .collect();
    let progress = &opts.progress;
    progress.plan(&durations_s);
    let wall = Instant::now();
    for index in selected {
        let setting = &sweep.settings[index];
        let label = &labels[index];
        let stopped = opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed));
        let started = local_time_now();
        let result = if stopped {
            SettingResult {
                status: "not run: the sweep was stopped".into(),
                ..blank_result(sweep, setting)
            }
        } else {
            progress.start_run(label, Some(setting.duration_s * setting.runs() as f64));
            let ply_dir = out.join("ply").join(format!("{index:03}"));
            run_setting(sweep, setting, ply_dir, opts)
        };
        let stopped_by_now = opts
            .stop
            .as_ref()
            .is_some_and(|s| s.load(Ordering::Relaxed));
        if result.is_ok() || !stopped_by_now {
            // A setting stopped (or never started) by a signal leaves no record: a merge names
            // it as missing.
            let record_file = sweep.record_path(&out, index);
            let record = SettingRecord {
                config: cfg.clone(),
                started,
                threads,
                result: result.clone(),
            };
            crate::shard::write_record(&record_file, &record).map_err(write_error(&record_file))?;
            if !opts.select.is_all() {
                report.files.push(record_file.display().to_string());
            }
        }
        report.failed += usize::from(!result.is_ok());
        report.results.push(result);
        score(&mut report.results);
        if !stopped {
            let scored = report.results.last().expect("just pushed");
            progress.finish_run(
                setting.duration_s * setting.runs() as f64,
                &finish_line(label, scored),
            );
        }
        report.wall_time_s = wall.elapsed().as_secs_f64();
        if opts.select.is_all() {
            write_tables(&report, &out)?;
        }
    }
    progress.done();
    if opts.select.is_all() {
        write_final(&mut report, &out)?;
    }
    Ok(report)
}

/// Merges the records that the shards of `sweep` left in `out` (`settings/`) into the sweep's
/// results, as [`run_sweep`] writes them for all its settings in one process; an error names
/// the settings without a record. The report's wall time is the sum of the settings'.
pub fn merge_sweep(sweep: &Sweep, out: &Path) -> Result<SweepReport, SweepError> {
    let units: Vec<(String, PathBuf)> = sweep
        .labels()
        .into_iter()
        .enumerate()
        .map(|(index, label)| (label, sweep.record_path(out, index)))
        .collect();
    let records: Vec<SettingRecord> =
        crate::shard::read_all_records(out, "settings", &units, &sweep.config)?;
    let started = crate::shard::earliest_start(&records);
    let threads = crate::shard::most_threads(&records);
    let mut report = blank_report(sweep, out, started, threads);
    report.results = records.into_iter().map(|r| r.result).collect();
    score(&mut report.results);
    report.failed = report.results.iter().filter(|r| !r.is_ok()).count();
    report.wall_time_s = report.results.iter().filter_map(|r| r.wall_time_s).sum();
    write_final(&mut report, out)?;
    Ok(report)
}

/// An error writing `path`.
fn write_error(path: &Path) -> impl FnOnce(std::io::Error) -> SweepError {
    let path = path.to_path_buf();
    move |source| SweepError::from(crate::config_error::ConfigError::write(&path, source))
}

/// The report of `sweep` in `out` before any setting.
fn blank_report(sweep: &Sweep, out: &Path, started: String, threads: usize) -> SweepReport {
    SweepReport {
        sweep: sweep.config.name.clone(),
        file: sweep.file.display().to_string(),
        config: sweep.config.clone(),
        out_dir: out.display().to_string(),
        started,
        threads,
        results: Vec::with_capacity(sweep.settings.len()),
        failed: 0,
        wall_time_s: 0.0,
        files: Vec::new(),
    }
}

/// Writes `results.csv` and `results.json`.
fn write_tables(report: &SweepReport, out: &Path) -> Result<(), SweepError> {
    let csv_path = out.join(RESULTS_CSV);
    std::fs::write(&csv_path, results_csv(&report.results)).map_err(write_error(&csv_path))?;
    let json_path = out.join(RESULTS_JSON);
    let json = serde_json::to_string_pretty(report).expect("plain data");
    std::fs::write(&json_path, json + "\n").map_err(write_error(&json_path))
}

/// Draws each study's charts, lists the files and writes the tables a last time.
fn write_final(report: &mut SweepReport, out: &Path) -> Result<(), SweepError> {
    let mut files = vec![out.join(RESULTS_CSV), out.join(RESULTS_JSON)];
    for study in &report.config.studies {
        if !report.results.iter().any(|r| r.study == study.name) {
            continue;
        }
        let note = match study.quantity {
            Quantity::RobotSpeed => format!(
                "reference {}",
                study.reference.as_deref().unwrap_or_default().join(" ")
            ),
            Quantity::CollapseRunout => "reference: the published law".into(),
        };
        let note = format!("{note}; {} threads", report.threads);
        files.extend(chart::write_pareto_chart(
            &report.results,
            &study.name,
            study.quantity.error_label(),
            &note,
            out,
        )?);
        if study.quantity == Quantity::CollapseRunout {
            files.extend(chart::write_law_chart(
                &report.results,
                &study.name,
                &format!("{} threads", report.threads),
                out,
            )?);
        }
    }
    report.files = files.iter().map(|p| p.display().to_string()).collect();
    write_tables(report, out)
}

/// A row for `setting` with nothing measured yet.
fn blank_result(sweep: &Sweep, setting: &Setting) -> SettingResult {
    let study = &sweep.config.studies[setting.study];
    SettingResult {
        study: study.name.clone(),
        setting: setting.name.clone(),
        quantity: study.quantity.name().into(),
        overrides: setting.overrides.clone(),
        is_reference: setting.is_reference,
        status: STATUS_OK.into(),
        ..SettingResult::default()
    }
}

/// Follows a run: the progress bar, and the robot's x position at the window's start and at
/// the latest frame.
struct Measure<'a> {
    progress: &'a Progress,
    /// Simulated time of the setting's earlier starts (s), for the progress bar.
    progress_offset_s: f64,
    window: Option<GaitWindow>,
    /// (time s, body x m) at the first frame at or after the window's start.
    start: Option<(f64, f64)>,
    /// (time s, body x m) at the latest frame.
    latest: Option<(f64, f64)>,
}

impl Observer for Measure<'_> {
    fn observe(&mut self, sim: &mut Simulation) -> Result<(), crate::scene::ObserverError> {
        let time_s = sim.time_s();
        self.progress
            .advance(self.progress_offset_s + time_s, String::new);
        if let (Some(window), Some(robot)) = (self.window, sim.robot()) {
            let x = robot.metrics().final_position_m[0];
            if self.start.is_none() && time_s >= window.from_s - WINDOW_TIME_TOLERANCE_S {
                self.start = Some((time_s, x));
            }
            self.latest = Some((time_s, x));
        }
        Ok(())
    }
}

impl Measure<'_> {
    /// Mean speed along x from the window's start to the latest frame (m/s).
    fn mean_speed_m_s(&self) -> Option<f64> {
        let ((t0, x0), (t1, x1)) = (self.start?, self.latest?);
        (t1 > t0).then(|| (x1 - x0) / (t1 - t0))
    }
}

/// Runs and measures one setting, once per start; failures become its status.
fn run_setting(
    sweep: &Sweep,
    setting: &Setting,
    ply_dir: PathBuf,
    opts: &SweepOptions,
) -> SettingResult {
    let mut result = blank_result(sweep, setting);
    let (mut wall_time_s, mut sim_time_s, mut substeps) = (0.0, 0.0, 0);
    let mut values = Vec::new();
    for run in 0..setting.runs() {
        let scene = match sweep.scene_of_run(setting, Some(run)) {
            Ok(scene) => scene,
            Err(e) => {
                result.status = e.to_string();
                return result;
            }
        };
        let run_opts = RunOptions {
            duration_s: Some(setting.duration_s),
            out_dir: Some(ply_dir.join(format!("start{run}"))),
            progress: Progress::none(),
            stop: opts.stop.clone(),
        };
        let mut measure = Measure {
            progress: &opts.progress,
            progress_offset_s: run as f64 * setting.duration_s,
            window: setting.window,
            start: None,
            latest: None,
        };
        let summary = match run_scene_observed(&scene, &run_opts, &mut measure) {
            Ok(summary) => summary,
            Err(e) => {
                result.status = if setting.runs() > 1 {
                    format!("start {run} (x = {} m): {e}", setting.start_x_m[run])
                } else {
                    e.to_string()
                };
                return result;
            }
        };
        wall_time_s += summary.wall_time_s;
        sim_time_s += summary.sim_time_s;
        substeps += summary.steps;
        result.starts = run + 1;
        result.wall_time_s = Some(wall_time_s);
        result.sim_time_s = Some(sim_time_s);
        result.wall_time_per_sim_s = Some(wall_time_s / sim_time_s);
        result.particles = Some(summary.particles);
        result.substeps = Some(substeps);
        if run == 0 {
            result.metrics = summary.metrics.clone();
        }
        if summary.stopped_early {
            result.status = format!(
                "stopped at t = {:.3} s of {} s",
                summary.sim_time_s, setting.duration_s
            );
            return result;
        }
        let metric = |name: &str| summary.metrics.get(name).and_then(|v| v.as_f64());
        let value = match sweep.config.studies[setting.study].quantity {
            Quantity::RobotSpeed => measure.mean_speed_m_s(),
            Quantity::CollapseRunout => {
                result.reference_value = metric("lube_2005_normalized_runout");
                metric("normalized_runout")
            }
        };
        match value {
            Some(v) => values.push(v),
            None => {
                result.status = "the run did not measure its quantity".into();
                return result;
            }
        }
    }
    let (mean, std) = mean_and_sample_std(&values).expect("one value per run, at least one run");
    result.value = Some(mean);
    result.value_std = std;
    result.start_values = values;
    result
}

/// The line printed when a setting's run is over.
fn finish_line(label: &str, r: &SettingResult) -> String {
    if r.is_ok() {
        format!(
            "{label}: {} (error {}), {} s per simulated s",
            fmt_opt(r.value, 4),
            error_text(r),
            fmt_opt(r.wall_time_per_sim_s, 2),
        )
    } else {
        format!("{label} failed: {}", r.status)
    }
}

/// The relative error in percent, with its noise where there is one: `12.3 ± 4.5 %`.
fn error_text(r: &SettingResult) -> String {
    match (r.relative_error, r.relative_error_noise) {
        (Some(e), Some(n)) => format!("{:.1} ± {:.1} %", 100.0 * e, 100.0 * n),
        (Some(e), None) => format!("{:.1} %", 100.0 * e),
        _ => "-".into(),
    }
}

/// `v` with `decimals`, or `-`.
fn fmt_opt(v: Option<f64>, decimals: usize) -> String {
    v.map_or("-".into(), |v| format!("{v:.decimals$}"))
}

/// The human summary of a report: one line per setting, `*` on the Pareto front.
pub fn report_table(report: &SweepReport) -> String {
    let mut text = format!(
        "{}: {} settings, {} failed, {:.0} s wall; results in {}\n",
        report.sweep,
        report.results.len(),
        report.failed,
        report.wall_time_s,
        report.out_dir
    );
    text.push_str(&format!(
        "{:<16} {:<40} {:>10} {:>10} {:>14} {:>10} {:>9}  status\n",
        "study", "setting", "value", "reference", "error", "wall/sim s", "particles"
    ));
    for r in &report.results {
        let name = format!(
            "{}{}",
            if r.pareto_optimal { "* " } else { "  " },
            r.setting
        );
        text.push_str(&format!(
            "{:<16} {:<40} {:>10} {:>10} {:>14} {:>10} {:>9}  {}\n",
            r.study,
            name,
            fmt_opt(r.value, 4),
            fmt_opt(r.reference_value, 4),
            error_text(r),
            fmt_opt(r.wall_time_per_sim_s, 2),
            r.particles.map_or("-".into(), |n| n.to_string()),
            r.status
        ));
    }
    text.push_str(
        "* on the study's Pareto front (no other setting is both cheaper and more accurate)\n",
    );
    text
}
