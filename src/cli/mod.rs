//! The command line: one file per group of commands, the options they share defined once
//! (`options.rs`), and the progress bars drawn from the library's progress reports
//! (`progress.rs`). The library below knows nothing of clap, progress bars or the exit code
//! (it prints only warnings on stderr); the `sandstep` binary only calls [`main`].

mod options;
pub mod progress;
mod run;
mod series;
mod stop;
mod tools;
mod urdf;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub use progress::Bars;
pub use urdf::UrdfArgs;

#[derive(Parser)]
#[command(
    name = "sandstep",
    version,
    about = "Granular terrain (MLS-MPM sand) for legged robots"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scene headless and print a summary.
    Run(run::RunArgs),
    /// Run a scene as a ROS 2 node (default: the robot on sand) until stopped or --duration.
    Node(run::NodeArgs),
    /// Sweep leg curvature, gait frequency and terrain model; measure the robot's speed.
    Experiment(series::ExperimentArgs),
    /// Measure what each setting costs and buys: error against wall time, Pareto front.
    Sweep(series::SweepArgs),
    /// Write a hexapod URDF (and its leg meshes) from leg and body parameters.
    Urdf(urdf::UrdfArgs),
    /// Summarise a recorded bag: distance, speed per gait cycle, sinkage, leg and body forces,
    /// commands.
    Analyze(tools::AnalyzeArgs),
    /// Bag tools: `reindex` finishes a bag whose recording was killed.
    #[command(subcommand)]
    Bag(tools::BagCommand),
    /// Calibrate resistive force theory: press a plate into the scene's MPM sand and fit zeta.
    CalibrateRft(tools::CalibrateRftArgs),
    /// Drag a vertical blade sideways through the scene's MPM sand (the calibration's bed) and
    /// print the force against it: a deterministic probe of the sand's resistance.
    DragBlade(tools::DragBladeArgs),
    /// Measure solver throughput on a 3D sand block collapsing under gravity.
    Bench(tools::BenchArgs),
    /// Measure how much faster than real time the robot walks on RFT ground, bag recorded.
    BenchRft(tools::BenchRftArgs),
}

/// Parses the command line, runs the command, and prints an error (with its causes) on stderr.
/// A job stopped by SIGINT or SIGTERM exits with 128 plus the signal once its outputs are
/// finished (130, 143).
pub fn main() -> ExitCode {
    stop::end_quietly_on_closed_pipe();
    let command = Cli::parse().command;
    // A bad SANDSTEP_SIMD is an error here, before any work, not a silent fallback later.
    if let Err(e) = crate::mpm::simd::InstructionSet::from_env() {
        eprintln!("error: {}: {e}", crate::mpm::simd::SIMD_ENV_VAR);
        return ExitCode::FAILURE;
    }
    let result = match command {
        Command::Run(args) => run::run(args),
        Command::Node(args) => run::node(args),
        Command::Experiment(args) => series::experiment(args),
        Command::Sweep(args) => series::sweep(args),
        Command::Urdf(args) => urdf::urdf(&args),
        Command::Analyze(args) => tools::analyze(args),
        Command::Bag(command) => tools::bag(command),
        Command::CalibrateRft(args) => tools::calibrate_rft(args),
        Command::DragBlade(args) => tools::drag_blade(args),
        Command::Bench(args) => tools::bench(args),
        Command::BenchRft(args) => tools::bench_rft(args),
    };
    if let Err(e) = &result {
        eprintln!("error: {e:#}");
    }
    match (stop::received_signal(), result) {
        (Some(signal), _) => {
            stop::tell_if_untold(signal);
            ExitCode::from(stop::exit_code(signal))
        }
        (None, Ok(())) => ExitCode::SUCCESS,
        (None, Err(_)) => ExitCode::FAILURE,
    }
}
