//! `sandstep run` (a scene headless, recorded) and `sandstep node` (a scene as a ROS 2 node).

use std::path::PathBuf;

use anyhow::Context;

use super::options::{check_duration, BagArgs, Json, MemoryLimit, Overrides, Threads};
use super::progress::Bars;
use super::stop::stop_flag;
use crate::ros::NodeRunOptions;
use crate::scene::{NoObserver, RunOptions, Scene};

/// The scene `sandstep node` runs without one: in the working directory, else in the source
/// tree the binary was built from.
const DEFAULT_NODE_SCENE: &str = "config/robot_on_sand.yaml";

/// `sandstep run`.
#[derive(clap::Args)]
pub struct RunArgs {
    /// Scene file (YAML), e.g. config/column_collapse.yaml.
    scene: PathBuf,
    /// Simulated time to run (s); overrides the scene's duration_s.
    #[arg(long)]
    duration: Option<f64>,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    memory: MemoryLimit,
    #[command(flatten)]
    overrides: Overrides,
    /// Output directory for snapshots (default out/<scene name>).
    #[arg(long)]
    out: Option<PathBuf>,
    #[command(flatten)]
    json: Json,
    #[command(flatten)]
    bag: BagArgs,
}

/// `sandstep node`.
#[derive(clap::Args)]
pub struct NodeArgs {
    /// Scene file (YAML); default config/robot_on_sand.yaml.
    scene: Option<PathBuf>,
    /// Stop after this much simulated time (s); default: run until Ctrl-C or SIGTERM.
    #[arg(long)]
    duration: Option<f64>,
    /// Pace the simulation to the wall clock and report the real-time factor reached.
    #[arg(long)]
    realtime: bool,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    memory: MemoryLimit,
    #[command(flatten)]
    overrides: Overrides,
    #[command(flatten)]
    json: Json,
    #[command(flatten)]
    bag: BagArgs,
}

/// Runs the scene headless with a progress bar, records its bag (finished on errors too) and
/// prints the summary.
pub fn run(args: RunArgs) -> anyhow::Result<()> {
    let stop = stop_flag()?;
    args.threads.apply()?;
    args.memory.apply()?;
    let duration_s = check_duration(args.duration)?;
    let scene = Scene::load(&args.scene, &args.overrides.overrides)?;
    let opts = RunOptions {
        duration_s,
        out_dir: args.out,
        progress: Bars::progress(args.json.show_progress()),
        stop: Some(stop),
    };
    let bag_dir = args.bag.dir(&scene.config.name);
    let run = crate::ros::record_run(&scene, &opts, bag_dir.as_deref(), &mut NoObserver)?;
    if let Some(bag) = &run.bag {
        eprintln!(
            "bag: {} ({} messages)",
            bag.dir.display(),
            bag.message_count
        );
    }
    let summary = run.summary;
    if args.json.json {
        println!("{}", serde_json::to_string(&summary)?);
        return Ok(());
    }
    // A run stopped inside its first substep simulated nothing: no rate to give.
    let rates = match summary.steps {
        0 => "nothing simulated".to_string(),
        _ => format!(
            "{:.2} s wall per sim s, {:.3e} particle-steps/s",
            summary.wall_time_per_sim_s, summary.particle_steps_per_s
        ),
    };
    println!(
        "{}: {} particles, {} steps, {:.3} s simulated in {:.2} s wall ({rates})",
        summary.scene, summary.particles, summary.steps, summary.sim_time_s, summary.wall_time_s,
    );
    if summary.stopped_early {
        println!(
            "  stopped early by {} at t = {:.3} s of {} s",
            super::stop::received_signal()
                .and_then(super::stop::signal_name)
                .unwrap_or("a stop request"),
            summary.sim_time_s,
            duration_s.unwrap_or(scene.config.duration_s)
        );
    }
    for (key, value) in &summary.metrics {
        println!("  {key}: {value}");
    }
    Ok(())
}

/// Runs the scene as a ROS 2 node until stopped or `--duration`, and prints its summary.
pub fn node(args: NodeArgs) -> anyhow::Result<()> {
    let stop = stop_flag()?;
    args.threads.apply()?;
    args.memory.apply()?;
    let duration_s = check_duration(args.duration)?;
    let file = args.scene.unwrap_or_else(default_node_scene);
    let scene = Scene::load(&file, &args.overrides.overrides)?;
    let opts = NodeRunOptions {
        duration_s,
        realtime: args.realtime,
        bag_dir: args.bag.dir(&scene.config.name),
        progress: Bars::progress(args.json.show_progress()),
        stop,
    };
    let summary = crate::ros::run_node(&scene, &opts)
        .with_context(|| format!("node on {}", scene.file.display()))?;
    if args.json.json {
        println!("{}", serde_json::to_string(&summary)?);
        return Ok(());
    }
    println!(
        "{}: {:.3} s simulated in {:.2} s wall (real-time factor {:.3}), {} commands, {} resets",
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
