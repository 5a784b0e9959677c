//! `sandstep experiment` (leg curvature, gait frequency and terrain model) and `sandstep sweep`
//! (cost against error per setting): series of recorded runs with their own progress bars.

use std::path::PathBuf;

use super::options::{Jobs, Json, MemoryLimit, Overrides, Threads};
use super::progress::Bars;
use super::stop::stop_flag;
use crate::experiment::{
    merge_experiment, report_table, run_experiment, Experiment, ExperimentOptions,
};
use crate::sweep::{merge_sweep, run_sweep, Sweep, SweepOptions};

/// `sandstep experiment`.
#[derive(clap::Args)]
pub struct ExperimentArgs {
    /// Experiment file (YAML), e.g. config/experiments/leg_curvature.yaml.
    experiment: PathBuf,
    /// Output folder (default out/experiments/<name>-<YYYYmmdd-HHMMSS>).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    memory: MemoryLimit,
    #[command(flatten)]
    overrides: Overrides,
    #[command(flatten)]
    json: Json,
    /// Continue the experiment in --out: keep its finished runs, run the rest (with --shard
    /// or --run: of those runs).
    #[arg(long, requires = "out", conflicts_with = "merge")]
    resume: bool,
    #[command(flatten)]
    jobs: Jobs,
}

/// `sandstep sweep`.
#[derive(clap::Args)]
pub struct SweepArgs {
    /// Sweep file (YAML), e.g. config/sweeps/accuracy.yaml.
    sweep: PathBuf,
    /// Output folder (default out/sweeps/<name>-<YYYYmmdd-HHMMSS>).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    memory: MemoryLimit,
    /// Run only this study (repeatable; default all).
    #[arg(long = "study", value_name = "NAME")]
    studies: Vec<String>,
    #[command(flatten)]
    json: Json,
    #[command(flatten)]
    jobs: Jobs,
}

/// Runs the experiment (or lists, runs a shard of or merges its runs), prints its table (or
/// `results.json` with `--json`), and fails if a run failed.
pub fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let experiment = Experiment::load(&args.experiment, &args.overrides.overrides)?;
    if args.jobs.list {
        experiment
            .runs()
            .iter()
            .for_each(|run| println!("{}", run.name));
        return Ok(());
    }
    let report = match (&args.out, args.jobs.merge) {
        (Some(out), true) => merge_experiment(&experiment, out)?,
        _ => {
            let stop = stop_flag()?;
            args.threads.apply()?;
            args.memory.apply()?;
            let opts = ExperimentOptions {
                out_dir: args.out,
                progress: Bars::progress(args.json.show_progress()),
                stop: Some(stop),
                resume: args.resume,
                select: args.jobs.selection(),
            };
            run_experiment(&experiment, &opts)?
        }
    };
    if args.json.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", report_table(&report));
    }
    let table = if args.jobs.selection().is_all() {
        crate::experiment::RESULTS_CSV
    } else {
        crate::experiment::RUNS_DIR
    };
    anyhow::ensure!(
        report.failed == 0,
        "{} of {} runs failed (see {}/{table})",
        report.failed,
        report.runs.len(),
        report.out_dir
    );
    Ok(())
}

/// Runs the sweep's settings (or lists, runs a shard of or merges them) and prints its table
/// (or `results.json` with `--json`).
pub fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let sweep = Sweep::load(&args.sweep)?.only_studies(&args.studies)?;
    if args.jobs.list {
        sweep.labels().iter().for_each(|label| println!("{label}"));
        return Ok(());
    }
    let report = match (&args.out, args.jobs.merge) {
        (Some(out), true) => merge_sweep(&sweep, out)?,
        _ => {
            let stop = stop_flag()?;
            args.threads.apply()?;
            args.memory.apply()?;
            let opts = SweepOptions {
                out_dir: args.out,
                progress: Bars::progress(args.json.show_progress()),
                stop: Some(stop),
                select: args.jobs.selection(),
            };
            run_sweep(&sweep, &opts)?
        }
    };
    if args.json.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", crate::sweep::report_table(&report));
    }
    Ok(())
}
