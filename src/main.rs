//! The `sandstep` command line.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};

use sandstep::scene::{run_scene, RunOptions, Scene};

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
    Run {
        /// Scene file (YAML), e.g. config/column_collapse.yaml.
        scene: PathBuf,
        /// Simulated time to run (s); overrides the scene's duration_s.
        #[arg(long)]
        duration: Option<f64>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Change one scene value, e.g. --set column_collapse.aspect_ratio=3 (repeatable).
        #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
        overrides: Vec<String>,
        /// Output directory for snapshots (default out/<scene name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Print one JSON object on stdout instead of the human summary.
        #[arg(long)]
        json: bool,
    },
    /// Write a hexapod URDF (and its leg meshes) from leg and body parameters.
    Urdf(sandstep::robot::UrdfArgs),
    /// Measure solver throughput on a 3D sand block collapsing under gravity.
    Bench {
        /// Number of particles (8 per cell).
        #[arg(long, default_value_t = 500_000)]
        particles: usize,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Timed substeps.
        #[arg(long, default_value_t = 50)]
        steps: u64,
        /// Print one JSON object on stdout.
        #[arg(long)]
        json: bool,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn set_threads(threads: Option<usize>) -> anyhow::Result<()> {
    if let Some(n) = threads {
        anyhow::ensure!(n > 0, "--threads must be at least 1");
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()?;
    }
    Ok(())
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Run {
            scene,
            duration,
            threads,
            overrides,
            out,
            json,
        } => {
            set_threads(threads)?;
            if let Some(d) = duration {
                anyhow::ensure!(d > 0.0 && d.is_finite(), "--duration must be > 0 seconds");
            }
            let scene = Scene::load(&scene, &overrides)?;
            let opts = RunOptions {
                duration_s: duration,
                out_dir: out,
                progress: !json,
            };
            let summary = run_scene(&scene, &opts)
                .with_context(|| format!("running {}", scene.file.display()))?;
            if json {
                println!("{}", serde_json::to_string(&summary)?);
            } else {
                println!(
                    "{}: {} particles, {} steps, {:.3} s simulated in {:.2} s wall \
                     ({:.2} s wall per sim s, {:.3e} particle-steps/s)",
                    summary.scene,
                    summary.particles,
                    summary.steps,
                    summary.sim_time_s,
                    summary.wall_time_s,
                    summary.wall_time_per_sim_s,
                    summary.particle_steps_per_s
                );
                for (key, value) in &summary.metrics {
                    println!("  {key}: {value}");
                }
            }
        }
        Command::Urdf(args) => sandstep::robot::run_urdf_command(&args)?,
        Command::Bench {
            particles,
            threads,
            steps,
            json,
        } => {
            set_threads(threads)?;
            anyhow::ensure!(particles >= 8, "--particles must be at least 8");
            let report = sandstep::bench::run(particles, steps)?;
            if json {
                println!("{}", serde_json::to_string(&report)?);
            } else {
                println!(
                    "{} particles, {} threads, {} steps in {:.2} s: {:.3e} particle-steps/s, \
                     {:.0} bytes/particle",
                    report.particles,
                    report.threads,
                    report.steps,
                    report.wall_time_s,
                    report.particle_steps_per_s,
                    report.bytes_per_particle
                );
                for (stage, rate) in &report.stages {
                    println!(
                        "  {stage:12} {:.3e} particle-steps/s",
                        rate.as_f64().unwrap_or(0.0)
                    );
                }
            }
        }
    }
    Ok(())
}
