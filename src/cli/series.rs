//! `sandstep experiment` (leg curvature, gait frequency and terrain model) and `sandstep sweep`
//! (cost against error per setting): series of recorded runs with their own progress bars.

use std::path::PathBuf;

use super::options::{Json, MemoryLimit, Overrides, Threads};
use super::progress::Bars;
use super::stop::stop_flag;
use crate::experiment::{report_table, run_experiment, Experiment, ExperimentOptions};
use crate::sweep::{run_sweep, Sweep, SweepOptions};

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
    /// Continue the experiment in --out: keep its finished runs, run the rest.
    #[arg(long, requires = "out")]
    resume: bool,
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
}

/// Runs the experiment, prints its table (or `results.json` with `--json`), and fails if a
/// run failed.
pub fn experiment(args: ExperimentArgs) -> anyhow::Result<()> {
    let stop = stop_flag()?;
    args.threads.apply()?;
    args.memory.apply()?;
    let experiment = Experiment::load(&args.experiment, &args.overrides.overrides)?;
    let opts = ExperimentOptions {
        out_dir: args.out,
        progress: Bars::progress(args.json.show_progress()),
        stop: Some(stop),
        resume: args.resume,
    };
    let report = run_experiment(&experiment, &opts)?;
    if args.json.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", report_table(&report));
    }
    anyhow::ensure!(
        report.failed == 0,
        "{} of {} runs failed (see {}/results.csv)",
        report.failed,
        report.runs.len(),
        report.out_dir
    );
    Ok(())
}

/// Runs the sweep's settings and prints its table (or `results.json` with `--json`).
pub fn sweep(args: SweepArgs) -> anyhow::Result<()> {
    let stop = stop_flag()?;
    args.threads.apply()?;
    args.memory.apply()?;
    let sweep = Sweep::load(&args.sweep)?.only_studies(&args.studies)?;
    let opts = SweepOptions {
        out_dir: args.out,
        progress: Bars::progress(args.json.show_progress()),
        stop: Some(stop),
    };
    let report = run_sweep(&sweep, &opts)?;
    if args.json.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", crate::sweep::report_table(&report));
    }
    Ok(())
}
