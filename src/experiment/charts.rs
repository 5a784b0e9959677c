//! The experiment's chart: robot speed against leg curvature, one line per gait frequency, one
//! panel per terrain model side by side on a common speed axis, with error bars of the spread
//! of the per-cycle speeds. PNG and SVG, with the plot font of `sandstep analyze`.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::config::TerrainModel;
use super::results::{summarize, RunResult};
use crate::analysis::plots::{
    chart, draw_legend, legend_line, line_style, padded_range, register_fonts, DrawError,
    DrawResult, PlotError, LABEL_FONT_SIZE, MARKER_RADIUS_PX, PLOT_SIZE,
};

/// File name (without extension) of the chart.
pub const SPEED_CHART: &str = "speed_vs_curvature";
/// Width of a panel (px); the chart is at least [`PLOT_SIZE`] wide.
const PANEL_WIDTH_PX: u32 = 800;
/// Radius of the hollow marker of one start's speed (px).
const START_MARKER_RADIUS_PX: u32 = 3;
/// Half the width of an error bar's caps (curvature units, 1/R).
const ERROR_CAP_HALF_WIDTH: f64 = 0.025;

/// One plotted point: curvature, mean speed, its spread (one standard deviation).
type Point = (f64, f64, f64);

/// The points of one terrain model at one frequency, by curvature; failed runs are left out.
/// With `several_starts`, each cell's mean over its completed starts and their standard
/// deviation (no bar below two); otherwise the run's mean per-cycle speed and the standard
/// deviation of its cycles.
fn points(
    runs: &[RunResult],
    model: TerrainModel,
    frequency_hz: f64,
    several_starts: bool,
) -> Vec<Point> {
    let runs: Vec<RunResult> = runs
        .iter()
        .filter(|r| r.terrain_model == model.name() && r.frequency_hz == frequency_hz)
        .cloned()
        .collect();
    let mut points: Vec<Point> = summarize(&runs)
        .iter()
        .filter_map(|cell| {
            let spread = if several_starts {
                cell.speed_std_m_s
            } else {
                runs.iter()
                    .find(|r| r.curvature_per_r == cell.curvature_per_r)
                    .filter(|r| r.is_ok())
                    .and_then(|r| r.speed_per_cycle_std_m_s)
            };
            Some((
                cell.curvature_per_r,
                cell.speed_mean_m_s?,
                spread.unwrap_or(0.0),
            ))
        })
        .collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// Each completed run's speed (curvature, mean per-cycle speed) of one model and frequency.
fn starts(runs: &[RunResult], model: TerrainModel, frequency_hz: f64) -> Vec<(f64, f64)> {
    runs.iter()
        .filter(|r| r.is_ok() && r.terrain_model == model.name() && r.frequency_hz == frequency_hz)
        .filter_map(|r| Some((r.curvature_per_r, r.speed_per_cycle_mean_m_s?)))
        .collect()
}

/// Whether any cell of `runs` has several starts.
fn several_starts(runs: &[RunResult]) -> bool {
    summarize(runs).iter().any(|cell| cell.starts > 1)
}

/// Writes `speed_vs_curvature.png` and `.svg` into `dir`: a panel per model in `models`, a
/// line per frequency in `frequencies_hz`.
pub fn write_speed_chart(
    runs: &[RunResult],
    models: &[TerrainModel],
    frequencies_hz: &[f64],
    dir: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    register_fonts()?;
    let size = (
        PLOT_SIZE.0.max(PANEL_WIDTH_PX * models.len() as u32),
        PLOT_SIZE.1,
    );
    let png = dir.join(format!("{SPEED_CHART}.png"));
    let svg = dir.join(format!("{SPEED_CHART}.svg"));
    let fail = |path: &Path| {
        let path = path.to_path_buf();
        move |source: DrawError| PlotError::Draw { path, source }
    };
    draw(
        &BitMapBackend::new(&png, size).into_drawing_area(),
        runs,
        models,
        frequencies_hz,
    )
    .map_err(fail(&png))?;
    draw(
        &SVGBackend::new(&svg, size).into_drawing_area(),
        runs,
        models,
        frequencies_hz,
    )
    .map_err(fail(&svg))?;
    Ok(vec![png, svg])
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    runs: &[RunResult],
    models: &[TerrainModel],
    frequencies_hz: &[f64],
) -> Result<(), DrawError> {
    root.fill(&WHITE)?;
    let several = several_starts(runs);
    // One speed axis for all panels, every bar and start and 0 included.
    let cells = models.iter().flat_map(|&m| {
        frequencies_hz
            .iter()
            .flat_map(move |&f| points(runs, m, f, several))
    });
    let each_start = models
        .iter()
        .flat_map(|&m| frequencies_hz.iter().flat_map(move |&f| starts(runs, m, f)));
    let speed_range = padded_range(
        cells
            .flat_map(|(_, v, s)| [v - s, v + s])
            .chain(each_start.map(|(_, v)| v))
            .chain([0.0]),
    );
    let panels = root.split_evenly((1, models.len().max(1)));
    for (panel, &model) in panels.iter().zip(models) {
        let layout = Panel {
            model,
            frequencies_hz,
            several_starts: several,
            speed_range: speed_range.clone(),
        };
        draw_panel(panel, runs, &layout)?;
    }
    Ok(root.present()?)
}

/// What one panel shows.
struct Panel<'a> {
    model: TerrainModel,
    frequencies_hz: &'a [f64],
    /// Whether cells pool several starts ([`points`]).
    several_starts: bool,
    speed_range: std::ops::Range<f64>,
}

fn draw_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    runs: &[RunResult],
    panel: &Panel,
) -> DrawResult<DB> {
    let Panel {
        model,
        frequencies_hz,
        several_starts,
        ref speed_range,
    } = *panel;
    let mut chart = chart(
        area,
        &format!("Speed vs leg curvature, {}", model.label()),
        -1.1..1.1,
        speed_range.clone(),
        "leg curvature (1/R): -1 reversed, 0 straight, +1 C-leg",
        "speed along x, mean per gait cycle (m/s)",
    )?;
    let mut any = false;
    let bars = if several_starts {
        "mean over starts, bars: +-1 std over starts, dots: each start"
    } else {
        "bars: +-1 std of the cycles"
    };
    for (i, &f) in frequencies_hz.iter().enumerate() {
        let pts = points(runs, model, f, several_starts);
        if pts.is_empty() {
            continue;
        }
        any = true;
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                pts.iter().map(|&(k, v, _)| (k, v)),
                line_style(color),
            ))?
            .label(format!("{f} Hz ({bars})"))
            .legend(legend_line(color));
        chart.draw_series(
            pts.iter()
                .map(|&(k, v, _)| Circle::new((k, v), MARKER_RADIUS_PX, color.filled())),
        )?;
        if several_starts {
            chart.draw_series(
                starts(runs, model, f)
                    .into_iter()
                    .map(|(k, v)| Circle::new((k, v), START_MARKER_RADIUS_PX, color)),
            )?;
        }
        // Error bars: a vertical line from v - s to v + s with caps.
        chart.draw_series(pts.iter().flat_map(|&(k, v, s)| {
            let c = ERROR_CAP_HALF_WIDTH;
            [
                PathElement::new(vec![(k, v - s), (k, v + s)], line_style(color)),
                PathElement::new(vec![(k - c, v - s), (k + c, v - s)], line_style(color)),
                PathElement::new(vec![(k - c, v + s), (k + c, v + s)], line_style(color)),
            ]
        }))?;
    }
    if any {
        draw_legend(&mut chart)?;
    } else {
        let failed = runs
            .iter()
            .filter(|r| r.terrain_model == model.name())
            .count();
        chart.draw_series(std::iter::once(Text::new(
            format!("no results ({failed} runs failed; see results.csv)"),
            (
                -0.9,
                chart.y_range().end - 0.1 * (chart.y_range().end - chart.y_range().start),
            ),
            ("sans-serif", LABEL_FONT_SIZE),
        )))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chart_files_are_written_with_a_failed_model_panel() {
        let dir = tempfile::tempdir().unwrap();
        let run = |k: f64, f: f64, model: &str, v: f64, ok: bool| RunResult {
            curvature_per_r: k,
            frequency_hz: f,
            terrain_model: model.into(),
            speed_per_cycle_mean_m_s: ok.then_some(v),
            speed_per_cycle_std_m_s: ok.then_some(0.1 * v),
            status: if ok { "ok".into() } else { "failed".into() },
            ..RunResult::default()
        };
        let runs = [
            run(-1.0, 2.0, "mpm", 0.02, true),
            run(1.0, 2.0, "mpm", 0.2, true),
            run(1.0, 1.0, "mpm", 0.1, true),
            run(1.0, 2.0, "rft", 0.0, false),
        ];
        assert_eq!(points(&runs, TerrainModel::Mpm, 2.0, false).len(), 2);
        let files = write_speed_chart(
            &runs,
            &[TerrainModel::Mpm, TerrainModel::Rft],
            &[1.0, 2.0],
            dir.path(),
        )
        .unwrap();
        assert_eq!(files.len(), 2);
        let png = std::fs::read(&files[0]).unwrap();
        assert!(png.starts_with(b"\x89PNG"));
        let svg = std::fs::read_to_string(&files[1]).unwrap();
        assert!(
            svg.contains("RFT") && svg.contains("no results"),
            "{svg:.200}"
        );
    }

    #[test]
    fn several_starts_plot_their_mean_and_spread() {
        let start = |v: f64, cycles_std: f64| RunResult {
            curvature_per_r: 1.0,
            frequency_hz: 4.0,
            terrain_model: "mpm".into(),
            speed_per_cycle_mean_m_s: Some(v),
            speed_per_cycle_std_m_s: Some(cycles_std),
            status: "ok".into(),
            ..RunResult::default()
        };
        let one = [start(0.3, 0.05)];
        assert_eq!(
            points(&one, TerrainModel::Mpm, 4.0, false),
            [(1.0, 0.3, 0.05)]
        );
        assert!(!several_starts(&one));
        let three = [start(0.3, 0.05), start(0.4, 0.05), start(0.5, 0.05)];
        assert!(several_starts(&three));
        let p = points(&three, TerrainModel::Mpm, 4.0, true);
        assert_eq!(p.len(), 1);
        assert!(
            (p[0].1 - 0.4).abs() < 1e-12 && (p[0].2 - 0.1).abs() < 1e-12,
            "{p:?}"
        );
        // Of several starts only one went through: its mean, and no bar (not its cycles').
        let failed = RunResult {
            status: "blew up".into(),
            speed_per_cycle_mean_m_s: None,
            ..start(0.0, 0.0)
        };
        let one_of_two = [start(0.3, 0.05), failed];
        assert_eq!(
            points(&one_of_two, TerrainModel::Mpm, 4.0, true),
            [(1.0, 0.3, 0.0)]
        );
        assert_eq!(starts(&three, TerrainModel::Mpm, 4.0).len(), 3);
        let dir = tempfile::tempdir().unwrap();
        let files = write_speed_chart(&three, &[TerrainModel::Mpm], &[4.0], dir.path()).unwrap();
        let svg = std::fs::read_to_string(&files[1]).unwrap();
        assert!(svg.contains("std over starts"), "{svg:.200}");
    }
}
