//! A study's charts, PNG and SVG, with the plot font of `sandstep analyze`:
//! - every study: error against cost on log axes, one point per setting labelled with its
//!   name, the Pareto front filled and joined by a line, the others hollow;
//! - a collapse study: its normalized runouts against aspect ratio beside Lube et al.'s law.

use std::ops::Range;
use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use super::SettingResult;
use crate::analysis::collapse::lube_normalized_runout;
use crate::analysis::plots::{
    draw_legend, legend_line, line_style, register_fonts, DrawError, PlotError,
    AXIS_DESC_FONT_SIZE, CAPTION_FONT_SIZE, LABEL_FONT_SIZE, LEGEND_BACKGROUND_OPACITY, MARGIN_PX,
    MARKER_RADIUS_PX, PLOT_SIZE, X_LABEL_AREA_PX, Y_LABEL_AREA_PX,
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

/// A chart that can be drawn on any plotters backend.
trait Chart {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError>;
}

/// Writes `chart` as `<stem>.png` and `<stem>.svg` into `dir`.
fn write_png_and_svg(
    chart: &impl Chart,
    dir: &Path,
    stem: &str,
) -> Result<Vec<PathBuf>, PlotError> {
    register_fonts()?;
    let mut files = Vec::new();
    for ext in ["png", "svg"] {
        let path = dir.join(format!("{stem}.{ext}"));
        let drawn = if ext == "png" {
            chart.draw(&BitMapBackend::new(&path, PLOT_SIZE).into_drawing_area())
        } else {
            chart.draw(&SVGBackend::new(&path, PLOT_SIZE).into_drawing_area())
        };
        drawn.map_err(|source| PlotError::Draw {
            path: path.clone(),
            source,
        })?;
        files.push(path);
    }
    Ok(files)
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
    let chart = ParetoChart {
        study,
        pts: points(results, study),
        y_desc,
        note,
    };
    write_png_and_svg(&chart, dir, study)
}

/// Error against cost.
struct ParetoChart<'a> {
    study: &'a str,
    pts: Vec<Point>,
    y_desc: &'a str,
    note: &'a str,
}

impl Chart for ParetoChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        draw(root, self.study, &self.pts, self.y_desc, self.note)
    }
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

/// Aspect ratio steps at which the law's lines are drawn.
const LAW_SAMPLES: usize = 200;
/// The band drawn around the law: its value times 1 -/+ this.
const LAW_BAND: f64 = 0.15;
/// Aspect ratios closer than this are one (each run measures its column's, which its grid's
/// particle layers round).
const SAME_ASPECT_RATIO: f64 = 0.01;
/// Headroom above the highest point or law value on the runout axis (fraction).
const RUNOUT_AXIS_HEADROOM: f64 = 0.15;

/// Writes `<study>_law.png` and `.svg` into `dir`: the study's normalized runouts against the
/// aspect ratio (from each run's metrics), labelled with the settings' names, beside Lube et
/// al.'s law and a band of +-15 % around it. Nothing is written for a study without runouts.
pub fn write_law_chart(
    results: &[SettingResult],
    study: &str,
    note: &str,
    dir: &Path,
) -> Result<Vec<PathBuf>, PlotError> {
    let mut pts: Vec<(f64, f64, String)> = results
        .iter()
        .filter(|r| r.study == study && r.is_ok())
        .filter_map(|r| {
            let a = r.metrics.get("aspect_ratio")?.as_f64()?;
            Some((a, r.value?, r.setting.clone()))
        })
        .collect();
    if pts.is_empty() {
        return Ok(Vec::new());
    }
    // Runs at one aspect ratio (several grids) next to each other, lowest runout first.
    pts.sort_by(|p, q| {
        let group = |a: f64| (a / SAME_ASPECT_RATIO).round() as i64;
        group(p.0).cmp(&group(q.0)).then(p.1.total_cmp(&q.1))
    });
    write_png_and_svg(&LawChart { study, pts, note }, dir, &format!("{study}_law"))
}

/// Normalized runout against aspect ratio, beside the law.
struct LawChart<'a> {
    study: &'a str,
    /// Aspect ratio, normalized runout, setting name; sorted by aspect ratio, then runout.
    pts: Vec<(f64, f64, String)>,
    note: &'a str,
}

impl LawChart<'_> {
    /// The law times `factor` as line segments (one per regime; none between them).
    fn law_segments(&self, a_max: f64, factor: f64) -> Vec<Vec<(f64, f64)>> {
        let mut segments = vec![Vec::new()];
        for i in 0..=LAW_SAMPLES {
            let a = a_max * i as f64 / LAW_SAMPLES as f64;
            match lube_normalized_runout(a as f32) {
                Some(law) => segments.last_mut().unwrap().push((a, law as f64 * factor)),
                None if !segments.last().unwrap().is_empty() => segments.push(Vec::new()),
                None => {}
            }
        }
        segments.retain(|s| s.len() > 1);
        segments
    }
}

impl Chart for LawChart<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), DrawError> {
        let e = DrawError::from;
        root.fill(&WHITE).map_err(e)?;
        let a_max = self.pts.iter().map(|p| p.0).fold(1.0, f64::max) * 1.1;
        let top = self
            .pts
            .iter()
            .map(|p| p.1)
            .chain(
                self.law_segments(a_max, 1.0 + LAW_BAND)
                    .concat()
                    .iter()
                    .map(|p| p.1),
            )
            .fold(0.0, f64::max)
            * (1.0 + RUNOUT_AXIS_HEADROOM);
        let mut chart = ChartBuilder::on(root)
            .caption(
                format!(
                    "{}: runout against Lube et al. 2005 ({})",
                    self.study, self.note
                ),
                ("sans-serif", CAPTION_FONT_SIZE),
            )
            .margin(MARGIN_PX)
            .x_label_area_size(X_LABEL_AREA_PX)
            .y_label_area_size(Y_LABEL_AREA_PX)
            .build_cartesian_2d(0.0..a_max, 0.0..top)
            .map_err(e)?;
        chart
            .configure_mesh()
            .x_desc("aspect ratio a = H_i / L_i")
            .y_desc("normalized runout (L_inf - L_i) / L_i")
            .label_style(("sans-serif", LABEL_FONT_SIZE))
            .axis_desc_style(("sans-serif", AXIS_DESC_FONT_SIZE))
            .draw()
            .map_err(e)?;
        let law_color = BLACK.to_rgba();
        let band_color = RGBAColor(150, 150, 150, 1.0);
        let point_color = Palette99::pick(0).to_rgba();
        for (factor, color, label) in [
            (
                1.0,
                law_color,
                "Lube et al. 2005: 1.2 a (a < 1.8), 1.9 a^(2/3) (a > 2.8)",
            ),
            (1.0 - LAW_BAND, band_color, "law -/+ 15 %"),
            (1.0 + LAW_BAND, band_color, ""),
        ] {
            for (i, segment) in self.law_segments(a_max, factor).into_iter().enumerate() {
                let series = chart
                    .draw_series(LineSeries::new(segment, line_style(color)))
                    .map_err(e)?;
                if i == 0 && !label.is_empty() {
                    series.label(label).legend(legend_line(color));
                }
            }
        }
        chart
            .draw_series(self.pts.iter().enumerate().map(|(i, (a, runout, name))| {
                // At one aspect ratio the lower runout is labelled below, the next above.
                let rank = self.pts[..i]
                    .iter()
                    .filter(|p| (p.0 - a).abs() < SAME_ASPECT_RATIO)
                    .count();
                EmptyElement::at((*a, *runout))
                    + Circle::new((0, 0), MARKER_RADIUS_PX, point_color.filled())
                    + Text::new(
                        name.clone(),
                        LABEL_OFFSETS_PX[(rank + 1) % LABEL_OFFSETS_PX.len()],
                        ("sans-serif", LABEL_FONT_SIZE),
                    )
            }))
            .map_err(e)?
            .label("measured")
            .legend(move |(x, y)| Circle::new((x + 10, y), MARKER_RADIUS_PX, point_color.filled()));
        draw_legend(&mut chart).map_err(e)?;
        Ok(root.present()?)
    }
}
