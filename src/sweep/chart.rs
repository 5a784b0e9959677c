//! A study's chart: error against cost on log axes, one point per setting labelled with its
//! name, the Pareto front filled and joined by a line, the others hollow. PNG and SVG, with the
//! plot font of `sandstep analyze`.

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::SettingResult;
use crate::analysis::plots::{
    line_style, register_fonts, DrawError, PlotError, AXIS_DESC_FONT_SIZE, CAPTION_FONT_SIZE,
    LABEL_FONT_SIZE, LEGEND_BACKGROUND_OPACITY, MARGIN_PX, MARKER_RADIUS_PX, PLOT_SIZE,
    X_LABEL_AREA_PX, Y_LABEL_AREA_PX,
};

/// Factor by which a log axis extends beyond its data on each side.
const LOG_AXIS_PADDING: f64 = 1.6;
/// Smallest span of a log axis (ratio of its ends), so a single point still gets an axis.
const MIN_LOG_AXIS_RATIO: f64 = 10.0;
/// Label offsets from their points (px), alternating above and below so that neighbours'
/// names do not overlap.
const LABEL_OFFSETS_PX: [(i32, i32); 2] = [(8, -20), (8, 6)];
/// Labels wished for on each log axis (plotters picks 1-2-5 steps).
const LOG_AXIS_LABELS: usize = 12;

/// A tick label: three significant digits, no trailing zeros.
fn short_number(v: f64) -> String {
    let text = format!(
        "{:.*}",
        (2 - libm::log10(v.abs()).floor() as i32).max(0) as usize,
        v
    );
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        text
    }
}

/// A plotted point: cost (wall time per simulated second), error, setting name, optimal.
type Point = (f64, f64, String, bool);

/// The study's settings that have a cost and a positive error (the reference, whose error is
/// 0 by definition, and failed runs are left out).
fn points(results: &[SettingResult], study: &str) -> Vec<Point> {
    results
        .iter()
        .filter(|r| r.study == study && r.is_ok() && !r.is_reference)
        .filter_map(|r| {
            let cost = r.wall_time_per_sim_s?;
            let error = r.relative_error?;
            (cost > 0.0 && error > 0.0).then(|| (cost, error, r.setting.clone(), r.pareto_optimal))
        })
        .collect()
}

/// A log axis around `values`: padded by [`LOG_AXIS_PADDING`], at least [`MIN_LOG_AXIS_RATIO`].
fn log_range(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .into_iter()
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !(lo > 0.0 && hi >= lo) {
        return 0.1..1.0;
    }
    let centre = (lo * hi).sqrt();
    let half_ratio = ((hi / lo).sqrt() * LOG_AXIS_PADDING).max(MIN_LOG_AXIS_RATIO.sqrt());
    centre / half_ratio..centre * half_ratio
}

/// Writes `<study>.png` and `<study>.svg` into `dir`; `note` (e.g. the reference) goes under
/// the caption.
pub fn write_pareto_chart(
    results: &[SettingResult],
    study: &str,
    y_desc: &str,
    note: &str,
    dir: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    register_fonts()?;
    let pts = points(results, study);
    let mut files = Vec::new();
    for ext in ["png", "svg"] {
        let path = dir.join(format!("{study}.{ext}"));
        let drawn = if ext == "png" {
            draw(
                &BitMapBackend::new(&path, PLOT_SIZE).into_drawing_area(),
                study,
                &pts,
                y_desc,
                note,
            )
        } else {
            draw(
                &SVGBackend::new(&path, PLOT_SIZE).into_drawing_area(),
                study,
                &pts,
                y_desc,
                note,
            )
        };
        drawn.map_err(|source| PlotError::Draw {
            path: path.clone(),
            source,
        })?;
        files.push(path);
    }
    Ok(files)
}

fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    study: &str,
    pts: &[Point],
    y_desc: &str,
    note: &str,
) -> Result<(), DrawError> {
    let e = DrawError::from;
    root.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(root)
        .caption(
            format!("{study}: error against cost ({note})"),
            ("sans-serif", CAPTION_FONT_SIZE),
        )
        .margin(MARGIN_PX)
        .x_label_area_size(X_LABEL_AREA_PX)
        .y_label_area_size(Y_LABEL_AREA_PX)
        .build_cartesian_2d(
            log_range(pts.iter().map(|p| p.0)).log_scale(),
            log_range(pts.iter().map(|p| p.1)).log_scale(),
        )
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("wall time per simulated second (s/s)")
        .y_desc(y_desc)
        .x_labels(LOG_AXIS_LABELS)
        .y_labels(LOG_AXIS_LABELS)
        .x_label_formatter(&|v| short_number(*v))
        .y_label_formatter(&|v| short_number(*v))
        .label_style(("sans-serif", LABEL_FONT_SIZE))
        .axis_desc_style(("sans-serif", AXIS_DESC_FONT_SIZE))
        .draw()
        .map_err(e)?;
    let front_color = Palette99::pick(0).to_rgba();
    let other_color = RGBAColor(120, 120, 120, 1.0);
    let mut front: Vec<(f64, f64)> = pts.iter().filter(|p| p.3).map(|p| (p.0, p.1)).collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0));
    chart
        .draw_series(LineSeries::new(front, line_style(front_color)))
        .map_err(e)?;
    chart
        .draw_series(
            pts.iter()
                .enumerate()
                .map(|(i, (cost, error, name, optimal))| {
                    let style = if *optimal {
                        front_color.filled()
                    } else {
                        line_style(other_color)
                    };
                    EmptyElement::at((*cost, *error))
                        + Circle::new((0, 0), MARKER_RADIUS_PX, style)
                        + Text::new(
                            name.clone(),
                            LABEL_OFFSETS_PX[i % LABEL_OFFSETS_PX.len()],
                            ("sans-serif", LABEL_FONT_SIZE),
                        )
                }),
        )
        .map_err(e)?
        .label("filled and joined: Pareto front; hollow: beaten on both")
        .legend(move |(x, y)| Circle::new((x + 10, y), MARKER_RADIUS_PX, front_color.filled()));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", LABEL_FONT_SIZE))
        .background_style(WHITE.mix(LEGEND_BACKGROUND_OPACITY))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;
    Ok(root.present()?)
}
