//! `sandstep analyze` (a recorded bag), `sandstep bag reindex` (a killed recording, finished),
//! `sandstep calibrate-rft` (RFT's zeta from the scene's sand) and `sandstep bench` (the sand
//! substep's throughput).

use std::path::PathBuf;

use anyhow::Context;

use super::options::{Json, Overrides, Threads};
use crate::analysis::bag::{analyze_bag_with, AnalysisOptions};
use crate::analysis::plots::write_plots;
use crate::mpm::simd::InstructionSet;
use crate::scene::Scene;
use crate::terrain::blade::BladeDrag;

/// Nanoseconds per second, for the bag's log times.
const NANOS_PER_SECOND: f64 = 1e9;

/// `sandstep analyze`.
#[derive(clap::Args)]
pub struct AnalyzeArgs {
    /// Bag directory (rosbag2, MCAP) or a bare .mcap file.
    bag: PathBuf,
    /// Analyse from this time on (s since the first body pose; e.g. after settling).
    #[arg(long, value_name = "S", default_value_t = 0.0)]
    start: f64,
    /// Write trajectory, speed, joint-angle and leg-force plots (PNG and SVG) into DIR.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    #[command(flatten)]
    json: Json,
}

/// `sandstep bag ...`.
#[derive(clap::Subcommand)]
pub enum BagCommand {
    /// Finish a bag whose recording was killed: write its MCAP summary and metadata.yaml from
    /// the messages of its complete chunks (the unfinished file is kept as *.unfinished).
    Reindex {
        /// Bag directory (without metadata.yaml).
        bag: PathBuf,
        #[command(flatten)]
        json: Json,
    },
}

/// Runs a `sandstep bag` command.
pub fn bag(command: BagCommand) -> anyhow::Result<()> {
    match command {
        BagCommand::Reindex { bag, json } => {
            let done = crate::bag::reindex(&bag)
                .with_context(|| format!("reindexing {}", bag.display()))?;
            if json.json {
                println!("{}", serde_json::to_string(&done)?);
            } else {
                println!(
                    "{}: {} messages recovered, up to t = {:.3} s; the unfinished file is kept as \
                     {}",
                    done.mcap_path.display(),
                    done.message_count,
                    done.last_time_ns.unwrap_or(0) as f64 / NANOS_PER_SECOND,
                    done.unfinished_path.display()
                );
            }
            Ok(())
        }
    }
}

/// `sandstep calibrate-rft`.
#[derive(clap::Args)]
pub struct CalibrateRftArgs {
    /// Scene file (YAML) with the sand, e.g. config/robot_on_sand.yaml; the test's settings
    /// are its terrain.rft.calibration.
    scene: PathBuf,
    /// Measure RFT's stress maps instead: a leg-sized plate moved through the sand at each
    /// attack and intrusion angle of terrain.rft.calibration.maps, and the generic form
    /// fitted to them (minutes).
    #[arg(long)]
    maps: bool,
    /// With --maps: also write the maps, with the sand and grid they belong to, to FILE
    /// (YAML), for a scene's terrain.rft.stress_maps.file.
    #[arg(long, value_name = "FILE", requires = "maps")]
    write: Option<PathBuf>,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    overrides: Overrides,
    #[command(flatten)]
    json: Json,
}

/// `sandstep drag-blade`.
#[derive(clap::Args)]
pub struct DragBladeArgs {
    /// Scene file (YAML) with the sand, e.g. config/robot_on_sand.yaml; the bed is its
    /// terrain.rft.calibration's (grid, side, depth, settling).
    scene: PathBuf,
    /// Blade width across the motion (m).
    #[arg(long, value_name = "M", default_value_t = 0.04)]
    width: f32,
    /// Blade height (m).
    #[arg(long, value_name = "M", default_value_t = 0.03)]
    height: f32,
    /// Height of the blade's top above the sand surface (m).
    #[arg(long, value_name = "M", default_value_t = 0.005)]
    top_above_surface: f32,
    /// Drag speed along +x (m/s); 0.3 is about a leg tip's at 2 Hz.
    #[arg(long, value_name = "M_S", default_value_t = 0.3)]
    speed: f32,
    /// Distance dragged (m).
    #[arg(long, value_name = "M", default_value_t = 0.06)]
    travel: f32,
    /// The blade's centre at the start, from the bed's centre along x (m); default: half the
    /// travel behind it.
    #[arg(long, value_name = "M", allow_hyphen_values = true)]
    start_x: Option<f32>,
    /// The same along y (m).
    #[arg(
        long,
        value_name = "M",
        allow_hyphen_values = true,
        default_value_t = 0.0
    )]
    start_y: f32,
    /// Force averaging window (s).
    #[arg(long, value_name = "S", default_value_t = 0.01)]
    window: f64,
    /// Blade thickness (m), below the grid spacing: a CPIC sheet.
    #[arg(long, value_name = "M", default_value_t = 0.001)]
    thickness: f32,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    overrides: Overrides,
    #[command(flatten)]
    json: Json,
}

/// Drags a blade through the scene's sand and prints the force against it per window.
pub fn drag_blade(args: DragBladeArgs) -> anyhow::Result<()> {
    args.threads.apply()?;
    let scene = Scene::load(&args.scene, &args.overrides.overrides)?;
    let blade = BladeDrag {
        width_m: args.width,
        height_m: args.height,
        top_above_surface_m: args.top_above_surface,
        speed_m_s: args.speed,
        travel_m: args.travel,
        start_offset_m: [args.start_x.unwrap_or(-0.5 * args.travel), args.start_y],
        window_s: args.window,
        thickness_m: args.thickness,
    };
    let r = scene.drag_blade(&blade)?;
    if args.json.json {
        println!("{}", serde_json::to_string(&r)?);
        return Ok(());
    }
    println!(
        "{}: blade {:.1} x {:.1} mm dragged {:.1} mm at {:.3} m/s through {} (dx {:.1} mm, {} \
         particles, {} substeps): {:.4} N over the first half, {:.4} N over the second, {:.1} s \
         wall",
        r.scene,
        blade.width_m * 1e3,
        blade.height_m * 1e3,
        blade.travel_m * 1e3,
        blade.speed_m_s,
        r.material,
        r.dx_m * 1e3,
        r.particles,
        r.substeps,
        r.first_half_force_n,
        r.second_half_force_n,
        r.wall_time_s
    );
    for s in &r.samples {
        println!("  travel {:6.1} mm: {:.4} N", s.depth_m * 1e3, s.force_n);
    }
    Ok(())
}

/// `sandstep bench`.
#[derive(clap::Args)]
pub struct BenchArgs {
    /// Number of particles (8 per cell).
    #[arg(long, default_value_t = 500_000)]
    particles: usize,
    #[command(flatten)]
    threads: Threads,
    /// Timed substeps.
    #[arg(long, default_value_t = 50)]
    steps: u64,
    /// Instruction set of the wide loops: auto (the best this CPU has), avx512, avx2 or
    /// portable. Default: $SANDSTEP_SIMD, else auto.
    #[arg(long)]
    simd: Option<String>,
    #[command(flatten)]
    json: Json,
}

/// `sandstep bench-rft`.
#[derive(clap::Args)]
pub struct BenchRftArgs {
    /// Scene file (YAML) with a robot; run with terrain.model=rft.
    #[arg(default_value = "config/robot_on_sand.yaml")]
    scene: PathBuf,
    /// Simulated time of each run (s).
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    duration: f64,
    /// Timed runs with the bag, each followed by one without (the bag's share).
    #[arg(long, value_name = "N", default_value_t = 5)]
    repeat: usize,
    #[command(flatten)]
    threads: Threads,
    #[command(flatten)]
    overrides: Overrides,
    #[command(flatten)]
    json: Json,
}

/// Analyses the bag (from `--start` on), writes plots with `--plots`, and prints the summary.
pub fn analyze(args: AnalyzeArgs) -> anyhow::Result<()> {
    let opts = AnalysisOptions {
        start_s: args.start,
        max_cycles: None,
    };
    let bag = &args.bag;
    let analysis =
        analyze_bag_with(bag, &opts).with_context(|| format!("analysing {}", bag.display()))?;
    let mut summary = analysis.summary.clone();
    if let Some(dir) = &args.plots {
        let written = write_plots(&analysis, dir)
            .with_context(|| format!("writing plots into {}", dir.display()))?;
        summary.plots = written
            .files
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        summary.notes.extend(written.notes);
    }
    if args.json.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print!("{summary}");
    }
    Ok(())
}

/// Presses a plate into the scene's sand, fits zeta and prints it with the force per depth.
pub fn calibrate_rft(args: CalibrateRftArgs) -> anyhow::Result<()> {
    args.threads.apply()?;
    let scene = Scene::load(&args.scene, &args.overrides.overrides)?;
    if args.maps {
        if args.write.is_some() {
            let maps = &scene.config.terrain.rft.calibration.maps;
            crate::terrain::stress_map::check_table_grid(&maps.betas_deg, &maps.gammas_deg)
                .context(
                    "--write: the angles of terrain.rft.calibration.maps do not form a table \
                     (betas within one period of 180 deg, gammas from -90 to 90 deg)",
                )?;
        }
        let progress = super::progress::Bars::progress(args.json.show_progress());
        let maps = scene.rft_stress_maps(&progress)?;
        if let Some(path) = &args.write {
            scene.write_stress_maps(&maps, path)?;
        }
        if args.json.json {
            println!("{}", serde_json::to_string(&maps)?);
        } else {
            print!("{}", stress_maps_table(&maps));
        }
        return Ok(());
    }
    let c = scene.calibrate_rft()?;
    if args.json.json {
        println!("{}", serde_json::to_string(&c)?);
        return Ok(());
    }
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
    Ok(())
}

/// The human summary of `calibrate-rft --maps`.
fn stress_maps_table(maps: &crate::terrain::stress_map::StressMaps) -> String {
    let fit = &maps.fit;
    let c = &fit.coefficients;
    let mut text = format!(
        "{}: RFT stress maps of material {}, dx {:.1} mm, {} particles a bed, settled surface \
         {:.2} mm, {:.0} s wall\n\
         zeta (fit) = {:.4e} N/m^3; rms residual: fit {:.3e} / {:.3e}, generic shape at its \
         best zeta {:.4e}: {:.3e} / {:.3e} N/m^3 (alpha_x / alpha_z)\n\
         coefficients (N/m^3): A00 {:.4e} A10 {:.4e} B11 {:.4e} B01 {:.4e} Bm11 {:.4e}\n\
         \x20                    C11 {:.4e} C01 {:.4e} Cm11 {:.4e} D10 {:.4e}\n\
         {:>8} {:>8} {:>12} {:>12} {:>12} {:>12}\n",
        maps.scene,
        maps.material,
        maps.dx_m * 1e3,
        maps.particles,
        maps.settled_surface_m * 1e3,
        maps.wall_time_s,
        fit.zeta_n_m3,
        fit.rms_residual_n_m3[0],
        fit.rms_residual_n_m3[1],
        fit.generic_zeta_n_m3,
        fit.generic_rms_residual_n_m3[0],
        fit.generic_rms_residual_n_m3[1],
        c.a00,
        c.a10,
        c.b11,
        c.b01,
        c.bm11,
        c.c11,
        c.c01,
        c.cm11,
        c.d10,
        "beta",
        "gamma",
        "alpha_x",
        "fit",
        "alpha_z",
        "fit"
    );
    let rows = fit
        .points
        .iter()
        .map(|p| {
            (
                p,
                c.alpha(p.beta_deg.to_radians(), p.gamma_deg.to_radians()),
                "",
            )
        })
        .chain(fit.checks.iter().map(|k| {
            let [x, z] = k.fitted_n_m3;
            (&k.measured, (x, z), "  (check, not fitted)")
        }));
    for (p, (x, z), note) in rows {
        text.push_str(&format!(
            "{:>8.1} {:>8.1} {:>12.4e} {:>12.4e} {:>12.4e} {:>12.4e}{note}\n",
            p.beta_deg, p.gamma_deg, p.alpha_x_n_m3, x, p.alpha_z_n_m3, z
        ));
    }
    text
}

/// Times the robot on RFT ground, bag recorded (and not, interleaved), and prints the
/// real-time factor's best and median.
pub fn bench_rft(args: BenchRftArgs) -> anyhow::Result<()> {
    use crate::bench_rft::{best_and_median, time_run};
    args.threads.apply()?;
    anyhow::ensure!(args.repeat >= 1, "--repeat must be at least 1");
    super::options::check_duration(Some(args.duration))?;
    let mut overrides = args.overrides.overrides.clone();
    overrides.push("terrain.model=rft".into());
    let scene = Scene::load(&args.scene, &overrides)?;
    let rft = &scene.config.terrain.rft;
    let law = rft.law();
    let bag_root = tempfile::Builder::new()
        .prefix("sandstep-bench-rft")
        .tempdir()
        .context("cannot make a folder for the bags")?;
    let mut runs = Vec::new();
    for i in 0..args.repeat {
        let bag_dir = bag_root.path().join(format!("run{i}"));
        for bag in [Some(bag_dir.as_path()), None] {
            let run = time_run(&scene, args.duration, bag)?;
            if !args.json.json {
                eprintln!(
                    "run {} {}: {:.3} s wall, {:.1}x real time",
                    i + 1,
                    if run.bag { "with bag" } else { "no bag  " },
                    run.wall_time_s,
                    run.real_time_factor()
                );
            }
            runs.push(run);
        }
        std::fs::remove_dir_all(&bag_dir).ok();
    }
    let factors = |bag: bool| -> Vec<f64> {
        runs.iter()
            .filter(|r| r.bag == bag)
            .map(|r| r.real_time_factor())
            .collect()
    };
    let (best, median) = best_and_median(&factors(true)).context("no runs")?;
    let (best_no_bag, median_no_bag) = best_and_median(&factors(false)).context("no runs")?;
    let first = runs[0];
    let step_s = first.sim_time_s / first.steps.max(1) as f64;
    let bag_mb_per_s = first.bag_bytes as f64 / 1e6 / first.sim_time_s;
    if args.json.json {
        let report = serde_json::json!({
            "scene": scene.file,
            "zeta_n_m3": law.zeta_n_m3(),
            "stress_maps": rft.stress_maps.as_ref().map(|m| &m.file),
            "step_s": step_s,
            "runs": runs,
            "real_time_factor_best": best,
            "real_time_factor_median": median,
            "real_time_factor_no_bag_best": best_no_bag,
            "real_time_factor_no_bag_median": median_no_bag,
            "bag_mb_per_sim_s": bag_mb_per_s,
        });
        println!("{report}");
        return Ok(());
    }
    let maps = rft
        .stress_maps
        .as_ref()
        .map_or("the generic shape".to_string(), |m| {
            let law = match m.law {
                crate::terrain::MapsLaw::Table => "table",
                crate::terrain::MapsLaw::Fit => "fit",
            };
            format!("the stress maps {} ({law})", m.file.display())
        });
    println!(
        "{}: RFT with {maps}, zeta {:.3e} N/m^3, {:.2} ms steps, {} runs of {} s simulated",
        scene.file.display(),
        law.zeta_n_m3(),
        step_s * 1e3,
        args.repeat,
        args.duration,
    );
    println!(
        "  with bag:    {best:.1}x real time best, {median:.1}x median \
         ({bag_mb_per_s:.3} MB of bag per simulated s)"
    );
    println!("  without bag: {best_no_bag:.1}x real time best, {median_no_bag:.1}x median");
    Ok(())
}

/// Times the sand substep on a collapsing block and prints particle-steps per second, per
/// stage too.
pub fn bench(args: BenchArgs) -> anyhow::Result<()> {
    args.threads.apply()?;
    anyhow::ensure!(args.particles >= 8, "--particles must be at least 8");
    let instruction_set = match &args.simd {
        Some(name) => InstructionSet::by_name(name).context("--simd")?,
        None => InstructionSet::from_env()?,
    };
    let report = crate::bench::run(args.particles, args.steps, instruction_set)?;
    if args.json.json {
        println!("{}", serde_json::to_string(&report)?);
        return Ok(());
    }
    println!(
        "{} particles, {} threads, {}, {} steps in {:.2} s: {:.3e} particle-steps/s, \
         {:.0} bytes/particle",
        report.particles,
        report.threads,
        instruction_set,
        report.steps,
        report.wall_time_s,
        report.particle_steps_per_s,
        report.bytes_per_particle
    );
    for (stage, rate) in &report.stages {
        println!(
            "  {stage:15} {:.3e} particle-steps/s",
            rate.as_f64().unwrap_or(0.0)
        );
    }
    Ok(())
}
