//! The `sandstep` command line.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::Context;
use clap::{Parser, Subcommand};

use sandstep::scene::{NoObserver, RunOptions, Scene};

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
        #[command(flatten)]
        bag: BagArgs,
    },
    /// Run a scene as a ROS 2 node (default: the robot on sand) until stopped or --duration.
    Node {
        /// Scene file (YAML); default config/robot_on_sand.yaml.
        scene: Option<PathBuf>,
        /// Stop after this much simulated time (s); default: run until Ctrl-C or SIGTERM.
        #[arg(long)]
        duration: Option<f64>,
        /// Pace the simulation to the wall clock and report the real-time factor reached.
        #[arg(long)]
        realtime: bool,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Change one scene or node value, e.g. --set node.name=sand1 (repeatable).
        #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
        overrides: Vec<String>,
        /// Print one JSON summary on stdout at the end.
        #[arg(long)]
        json: bool,
        #[command(flatten)]
        bag: BagArgs,
    },
    /// Sweep leg curvature, gait frequency and terrain model; measure the robot's speed.
    Experiment {
        /// Experiment file (YAML), e.g. config/experiments/leg_curvature.yaml.
        experiment: PathBuf,
        /// Output folder (default out/experiments/<name>-<YYYYmmdd-HHMMSS>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Change one experiment value, e.g. --set cycles=2 (repeatable).
        #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
        overrides: Vec<String>,
        /// Print results.json on stdout instead of the table.
        #[arg(long)]
        json: bool,
        /// Continue the experiment in --out: keep its finished runs, run the rest.
        #[arg(long, requires = "out")]
        resume: bool,
    },
    /// Measure what each setting costs and buys: error against wall time, Pareto front.
    Sweep {
        /// Sweep file (YAML), e.g. config/sweeps/accuracy.yaml.
        sweep: PathBuf,
        /// Output folder (default out/sweeps/<name>-<YYYYmmdd-HHMMSS>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Run only this study (repeatable; default all).
        #[arg(long = "study", value_name = "NAME")]
        studies: Vec<String>,
        /// Print results.json on stdout instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Write a hexapod URDF (and its leg meshes) from leg and body parameters.
    Urdf(sandstep::robot::UrdfArgs),
    /// Summarise a recorded bag: distance, speed per gait cycle, sinkage, leg forces, commands.
    Analyze {
        /// Bag directory (rosbag2, MCAP) or a bare .mcap file.
        bag: PathBuf,
        /// Analyse from this time on (s since the first body pose; e.g. after settling).
        #[arg(long, value_name = "S", default_value_t = 0.0)]
        start: f64,
        /// Write trajectory, speed, joint-angle and leg-force plots (PNG and SVG) into DIR.
        #[arg(long, value_name = "DIR")]
        plots: Option<PathBuf>,
        /// Print one JSON object on stdout instead of the human summary.
        #[arg(long)]
        json: bool,
    },
    /// Calibrate resistive force theory: press a plate into the scene's MPM sand and fit zeta.
    CalibrateRft {
        /// Scene file (YAML) with the sand, e.g. config/robot_on_sand.yaml; the test's settings
        /// are its terrain.rft.calibration.
        scene: PathBuf,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Change one scene value, e.g. --set terrain.rft.calibration.dx_m=0.01 (repeatable).
        #[arg(long = "set", value_name = "KEY.PATH=VALUE")]
        overrides: Vec<String>,
        /// Print one JSON object on stdout instead of the human summary.
        #[arg(long)]
        json: bool,
    },
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

/// Where a run records its bag.
#[derive(clap::Args)]
struct BagArgs {
    /// Bag directory to create (default bags/<scene>-<YYYYmmdd-HHMMSS>).
    #[arg(long = "bag", value_name = "DIR", conflicts_with = "no_bag")]
    dir: Option<PathBuf>,
    /// Do not record a bag.
    #[arg(long)]
    no_bag: bool,
}

/// Parent of the default bag directories.
const DEFAULT_BAG_PARENT: &str = "bags";
/// The scene `sandstep node` runs without one: in the working directory, else in the source
/// tree the binary was built from.
const DEFAULT_NODE_SCENE: &str = "config/robot_on_sand.yaml";

impl BagArgs {
    /// The bag directory for `scene_name`, or `None` with `--no-bag`.
    fn dir(&self, scene_name: &str) -> Option<PathBuf> {
        if self.no_bag {
            return None;
        }
        Some(self.dir.clone().unwrap_or_else(|| {
            sandstep::ros::default_bag_dir(std::path::Path::new(DEFAULT_BAG_PARENT), scene_name)
        }))
    }
}

/// A flag set by the first Ctrl-C or SIGTERM; a second one exits at once.
fn stop_flag() -> anyhow::Result<Arc<AtomicBool>> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || {
        if flag.swap(true, Ordering::SeqCst) {
            eprintln!("\nstopping now");
            std::process::exit(130);
        }
        eprintln!("\nstopping after this step (again to quit at once)");
    })?;
    Ok(stop)
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

fn check_duration(duration: Option<f64>) -> anyhow::Result<()> {
    if let Some(d) = duration {
        anyhow::ensure!(d > 0.0 && d.is_finite(), "--duration must be > 0 seconds");
    }
    Ok(())
}

fn default_node_scene() -> PathBuf {
    let here = PathBuf::from(DEFAULT_NODE_SCENE);
    if here.exists() {
        here
    } else {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(DEFAULT_NODE_SCENE)
    }
}

/// Runs `scene`, recording into `bag_dir` if given; the bag is finished on errors too.
fn run_recorded(
    scene: &Scene,
    opts: &RunOptions,
    bag_dir: Option<PathBuf>,
) -> anyhow::Result<sandstep::scene::RunSummary> {
    let run = sandstep::ros::record_run(scene, opts, bag_dir.as_deref(), &mut NoObserver)?;
    if let Some(bag) = &run.bag {
        eprintln!(
            "bag: {} ({} messages)",
            bag.dir.display(),
            bag.message_count
        );
    }
    Ok(run.summary)
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
            bag,
        } => {
            set_threads(threads)?;
            check_duration(duration)?;
            let scene = Scene::load(&scene, &overrides)?;
            let opts = RunOptions {
                duration_s: duration,
                out_dir: out,
                progress: !json,
                stop: Some(stop_flag()?),
            };
            let summary = run_recorded(&scene, &opts, bag.dir(&scene.config.name))?;
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
        Command::Node {
            scene,
            duration,
            realtime,
            threads,
            overrides,
            json,
            bag,
        } => {
            set_threads(threads)?;
            check_duration(duration)?;
            let file = scene.unwrap_or_else(default_node_scene);
            let scene = Scene::load(&file, &overrides)?;
            let opts = sandstep::ros::NodeRunOptions {
                duration_s: duration,
                realtime,
                bag_dir: bag.dir(&scene.config.name),
                progress: !json,
                stop: stop_flag()?,
            };
            let summary = sandstep::ros::run_node(&scene, &opts)
                .with_context(|| format!("node on {}", scene.file.display()))?;
            if json {
                println!("{}", serde_json::to_string(&summary)?);
            } else {
                println!(
                    "{}: {:.3} s simulated in {:.2} s wall (real-time factor {:.3}), \
                     {} commands, {} resets",
                    summary.node,
                    summary.sim_time_s,
                    summary.wall_time_s,
                    summary.real_time_factor,
                    summary.commands_received,
                    summary.resets
                );
                if let Some(bag) = &summary.bag {
                    println!(
                        "  bag: {} ({} messages)",
                        bag.dir.display(),
                        bag.message_count
                    );
                }
            }
        }
        Command::Experiment {
            experiment,
            out,
            threads,
            overrides,
            json,
            resume,
        } => {
            set_threads(threads)?;
            let experiment = sandstep::experiment::Experiment::load(&experiment, &overrides)?;
            let opts = sandstep::experiment::ExperimentOptions {
                out_dir: out,
                progress: !json,
                stop: Some(stop_flag()?),
                resume,
            };
            let report = sandstep::experiment::run_experiment(&experiment, &opts)?;
            if json {
                println!("{}", serde_json::to_string(&report)?);
            } else {
                print!("{}", sandstep::experiment::report_table(&report));
            }
            anyhow::ensure!(
                report.failed == 0,
                "{} of {} runs failed (see {}/results.csv)",
                report.failed,
                report.runs.len(),
                report.out_dir
            );
        }
        Command::Sweep {
            sweep,
            out,
            threads,
            studies,
            json,
        } => {
            set_threads(threads)?;
            let sweep = sandstep::sweep::Sweep::load(&sweep)?.only_studies(&studies)?;
            let opts = sandstep::sweep::SweepOptions {
                out_dir: out,
                progress: !json,
                stop: Some(stop_flag()?),
            };
            let report = sandstep::sweep::run_sweep(&sweep, &opts)?;
            if json {
                println!("{}", serde_json::to_string(&report)?);
            } else {
                print!("{}", sandstep::sweep::report_table(&report));
            }
        }
        Command::Urdf(args) => sandstep::robot::run_urdf_command(&args)?,
        Command::Analyze {
            bag,
            start,
            plots,
            json,
        } => {
            let opts = sandstep::analysis::bag::AnalysisOptions {
                start_s: start,
                max_cycles: None,
            };
            sandstep::analysis::bag::run_analyze_command(&bag, &opts, plots.as_deref(), json)?
        }
        Command::CalibrateRft {
            scene,
            threads,
            overrides,
            json,
        } => {
            set_threads(threads)?;
            let scene = Scene::load(&scene, &overrides)?;
            let c = sandstep::scene::calibrate_rft::calibrate_rft(&scene)?;
            if json {
                println!("{}", serde_json::to_string(&c)?);
            } else {
                println!(
                    "{}: zeta = {:.4e} N/m^3 (R^2 {:.3}) for material {}: plate {:.1} mm square \
                     ({:.3e} m^2) pressed at {:.3} m/s to {:.1} mm, dx {:.1} mm, {} particles, \
                     {:.1} s wall",
                    c.scene,
                    c.zeta_n_m3,
                    c.r_squared,
                    c.material,
                    c.plate_side_m * 1e3,
                    c.plate_area_m2,
                    c.speed_m_s,
                    c.final_depth_m * 1e3,
                    c.dx_m * 1e3,
                    c.particles,
                    c.wall_time_s
                );
                for cell in &c.cells {
                    println!(
                        "  depth {:5.1} mm: MPM {:.4} N, RFT {:.4} N",
                        cell.depth_m * 1e3,
                        cell.force_n,
                        c.zeta_n_m3 * c.plate_area_m2 * cell.depth_m
                    );
                }
            }
        }
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
