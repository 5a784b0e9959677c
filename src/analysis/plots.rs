//! Plots of an analysed bag (`sandstep analyze --plots DIR`), each as PNG and SVG:
//! `trajectory_xy`, `speed`, `joint_angles` and `leg_forces`.
//!
//! Text is drawn with Open Sans Regular (Apache-2.0, `assets/fonts/`), embedded in the binary
//! and registered with plotters on first use, so plots render the same on a machine without
//! system fonts. (A proportional font: plotters places each glyph at its advance without its
//! side bearing, which spaces a monospaced font's narrow glyphs oddly.)

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};

use super::bag::{BagAnalysis, BagSeries, NamedSeries};

/// Pixel size of the PNGs and of the SVG canvases.
pub(crate) const PLOT_SIZE: (u32, u32) = (1200, 720);
pub(crate) const CAPTION_FONT_SIZE: u32 = 28;
pub(crate) const AXIS_DESC_FONT_SIZE: u32 = 20;
pub(crate) const LABEL_FONT_SIZE: u32 = 16;
pub(crate) const LEGEND_FONT_SIZE: u32 = 16;
pub(crate) const MARGIN_PX: u32 = 20;
pub(crate) const X_LABEL_AREA_PX: u32 = 55;
pub(crate) const Y_LABEL_AREA_PX: u32 = 85;
pub(crate) const LINE_WIDTH_PX: u32 = 2;
pub(crate) const MARKER_RADIUS_PX: u32 = 6;
/// Length of the line sample in a legend entry.
pub(crate) const LEGEND_LINE_PX: i32 = 20;
/// Fraction of a data span added on each side of an axis.
const AXIS_PADDING: f64 = 0.05;
/// Smallest span (in data units) of an axis, so a constant series still gets an axis.
const MIN_AXIS_SPAN: f64 = 1e-3;
/// Opacity of the legend background.
pub(crate) const LEGEND_BACKGROUND_OPACITY: f64 = 0.85;
/// The font family names plotters asks for, all served by the embedded font.
const FONT_FAMILIES: [&str; 3] = ["sans-serif", "serif", "monospace"];
/// Open Sans Regular (see `assets/fonts/README.md`).
static PLOT_FONT: &[u8] = include_bytes!("../../assets/fonts/OpenSans-Regular.ttf");

/// What [`write_plots`] wrote and what it skipped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlotsWritten {
    /// Files written (PNG and SVG of each plot).
    pub files: Vec<PathBuf>,
    /// Plots skipped and why (e.g. no leg wrenches in the bag).
    pub notes: Vec<String>,
}

/// Why plots could not be written.
#[derive(thiserror::Error, Debug)]
pub enum PlotError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {source}", path.display())]
    Draw { path: PathBuf, source: DrawError },
    #[error("the embedded plot font did not load")]
    Font,
}

/// A plotters error met while drawing, as its message: plotters' error type is generic over
/// the drawing backend, so every chart (PNG or SVG) reports this one type.
#[derive(thiserror::Error, Debug, Clone)]
#[error("{0}")]
pub struct DrawError(String);

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for DrawError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        DrawError(e.to_string())
    }
}

/// Registers the embedded font for every family plotters uses, once per process.
pub(crate) fn register_fonts() -> Result<(), PlotError> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        FONT_FAMILIES
            .iter()
            .all(|family| register_font(family, FontStyle::Normal, PLOT_FONT).is_ok())
    });
    if ok {
        Ok(())
    } else {
        Err(PlotError::Font)
    }
}

/// The plots, in the order they are written.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Plot {
    TrajectoryXy,
    Speed,
    JointAngles,
    LegForces,
}

impl Plot {
    const ALL: [Plot; 4] = [
        Plot::TrajectoryXy,
        Plot::Speed,
        Plot::JointAngles,
        Plot::LegForces,
    ];

    /// File name without extension.
    fn file_stem(self) -> &'static str {
        match self {
            Plot::TrajectoryXy => "trajectory_xy",
            Plot::Speed => "speed",
            Plot::JointAngles => "joint_angles",
            Plot::LegForces => "leg_forces",
        }
    }

    /// Why the plot has nothing to show, if so.
    fn missing_data(self, series: &BagSeries) -> Option<&'static str> {
        match self {
            Plot::TrajectoryXy if series.body_position.is_empty() => Some("no body poses"),
            Plot::Speed if series.speed.is_empty() && series.cycles.is_empty() => {
                Some("too few body poses for a speed")
            }
            Plot::JointAngles if series.joint_angles.is_empty() => Some("no /joint_states"),
            Plot::LegForces if series.leg_forces.is_empty() => {
                Some("no /leg_wrenches/* topics (rigid ground?)")
            }
            _ => None,
        }
    }

    fn draw<DB: DrawingBackend>(
        self,
        root: &DrawingArea<DB, Shift>,
        series: &BagSeries,
    ) -> Result<(), DrawError> {
        root.fill(&WHITE)?;
        match self {
            Plot::TrajectoryXy => draw_trajectory(root, series),
            Plot::Speed => draw_speed(root, series),
            Plot::JointAngles => draw_named(
                root,
                "Joint angles",
                "angle (rad, unwrapped)",
                &series.joint_angles,
            ),
            Plot::LegForces => draw_named(
                root,
                "Sand force on each leg",
                "force magnitude |F| (N)",
                &series.leg_forces,
            ),
        }?;
        Ok(root.present()?)
    }
}

/// Writes `trajectory_xy`, `speed`, `joint_angles` and `leg_forces` as `.png` and `.svg` into
/// `dir` (created if needed). A plot without data is skipped with a note.
pub fn write_plots(analysis: &BagAnalysis, dir: &Path) -> Result<PlotsWritten, PlotError> {
    register_fonts()?;
    std::fs::create_dir_all(dir).map_err(|source| PlotError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let series = &analysis.series;
    let mut written = PlotsWritten::default();
    for plot in Plot::ALL {
        if let Some(reason) = plot.missing_data(series) {
            written
                .notes
                .push(format!("plot {} skipped: {reason}", plot.file_stem()));
            continue;
        }
        let png = dir.join(format!("{}.png", plot.file_stem()));
        let draw_error = |path: &Path| {
            let path = path.to_path_buf();
            move |source| PlotError::Draw { path, source }
        };
        plot.draw(
            &BitMapBackend::new(&png, PLOT_SIZE).into_drawing_area(),
            series,
        )
        .map_err(draw_error(&png))?;
        let svg = dir.join(format!("{}.svg", plot.file_stem()));
        plot.draw(
            &SVGBackend::new(&svg, PLOT_SIZE).into_drawing_area(),
            series,
        )
        .map_err(draw_error(&svg))?;
        written.files.extend([png, svg]);
    }
    Ok(written)
}

pub(crate) type DrawResult<DB> =
    Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// A chart with f64 axes.
pub(crate) type XyChart<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;

/// `[min, max]` of `values` padded by [`AXIS_PADDING`], at least [`MIN_AXIS_SPAN`] wide.
pub(crate) fn padded_range(values: impl IntoIterator<Item = f64>) -> Range<f64> {
    let (lo, hi) = values
        .into_iter()
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return 0.0..1.0;
    }
    let centre = 0.5 * (lo + hi);
    let half = (0.5 * (hi - lo) * (1.0 + 2.0 * AXIS_PADDING)).max(0.5 * MIN_AXIS_SPAN);
    centre - half..centre + half
}

pub(crate) fn line_style(color: RGBAColor) -> ShapeStyle {
    ShapeStyle::from(color).stroke_width(LINE_WIDTH_PX)
}

pub(crate) fn legend_line(color: RGBAColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + LEGEND_LINE_PX, y)], line_style(color))
}

/// The chart frame shared by every plot: caption, label areas and labelled axes.
pub(crate) fn chart<'a, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, Shift>,
    caption: &str,
    x: Range<f64>,
    y: Range<f64>,
    x_desc: &str,
    y_desc: &str,
) -> Result<XyChart<'a, DB>, DrawingAreaErrorKind<DB::ErrorType>> {
    let mut chart = ChartBuilder::on(root)
        .caption(caption, ("sans-serif", CAPTION_FONT_SIZE))
        .margin(MARGIN_PX)
        .x_label_area_size(X_LABEL_AREA_PX)
        .y_label_area_size(Y_LABEL_AREA_PX)
        .build_cartesian_2d(x, y)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .label_style(("sans-serif", LABEL_FONT_SIZE))
        .axis_desc_style(("sans-serif", AXIS_DESC_FONT_SIZE))
        .draw()?;
    Ok(chart)
}

pub(crate) fn draw_legend<'a, DB: DrawingBackend + 'a>(
    chart: &mut XyChart<'a, DB>,
) -> DrawResult<DB> {
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(("sans-serif", LEGEND_FONT_SIZE))
        .background_style(WHITE.mix(LEGEND_BACKGROUND_OPACITY))
        .border_style(BLACK)
        .draw()
}

/// Body path seen from above: y against x, start and end marked.
fn draw_trajectory<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &BagSeries,
) -> DrawResult<DB> {
    let xy: Vec<(f64, f64)> = series.body_position.iter().map(|p| (p[1], p[2])).collect();
    let mut chart = chart(
        root,
        "Body trajectory (odom frame, seen from above)",
        padded_range(xy.iter().map(|p| p.0)),
        padded_range(xy.iter().map(|p| p.1)),
        "x, forward (m)",
        "y, left (m)",
    )?;
    let path_color = BLUE.to_rgba();
    chart
        .draw_series(LineSeries::new(xy.iter().copied(), line_style(path_color)))?
        .label("body (base_link)")
        .legend(legend_line(path_color));
    for (point, color, label) in [
        (xy.first(), GREEN.to_rgba(), "start"),
        (xy.last(), RED.to_rgba(), "end"),
    ] {
        if let Some(&p) = point {
            chart
                .draw_series(std::iter::once(Circle::new(
                    p,
                    MARKER_RADIUS_PX,
                    color.filled(),
                )))?
                .label(label)
                .legend(move |(x, y)| {
                    Circle::new(
                        (x + LEGEND_LINE_PX / 2, y),
                        MARKER_RADIUS_PX,
                        color.filled(),
                    )
                });
        }
    }
    draw_legend(&mut chart)
}

/// Smoothed speed over time and the speed of each gait cycle as a step over the cycle.
fn draw_speed<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    series: &BagSeries,
) -> DrawResult<DB> {
    let cycle_points = series
        .cycles
        .iter()
        .flat_map(|c| [(c.start_s, c.speed_m_s), (c.end_s, c.speed_m_s)]);
    let all_points: Vec<(f64, f64)> = series.speed.iter().copied().chain(cycle_points).collect();
    let mut chart = chart(
        root,
        "Body speed along x",
        padded_range(all_points.iter().map(|p| p.0)),
        padded_range(all_points.iter().map(|p| p.1).chain([0.0])),
        "time (s)",
        "speed along x (m/s)",
    )?;
    let smoothed_color = BLUE.to_rgba();
    chart
        .draw_series(LineSeries::new(
            series.speed.iter().copied(),
            line_style(smoothed_color),
        ))?
        .label(format!(
            "dx/dt over a {:.3} s window",
            series.speed_window_s
        ))
        .legend(legend_line(smoothed_color));
    let cycle_color = RED.to_rgba();
    for (i, cycle) in series.cycles.iter().enumerate() {
        let step = [
            (cycle.start_s, cycle.speed_m_s),
            (cycle.end_s, cycle.speed_m_s),
        ];
        let drawn = chart.draw_series(LineSeries::new(
            step,
            line_style(cycle_color).stroke_width(2 * LINE_WIDTH_PX),
        ))?;
        if i == 0 {
            drawn
                .label("per gait cycle")
                .legend(legend_line(cycle_color));
        }
    }
    draw_legend(&mut chart)
}

/// One line per named series against time, coloured from a palette, with a legend.
fn draw_named<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    caption: &str,
    y_desc: &str,
    lines: &[NamedSeries],
) -> DrawResult<DB> {
    let points = || lines.iter().flat_map(|s| s.points.iter());
    let mut chart = chart(
        root,
        caption,
        padded_range(points().map(|p| p.0)),
        padded_range(points().map(|p| p.1)),
        "time (s)",
        y_desc,
    )?;
    for (i, line) in lines.iter().enumerate() {
        let color = Palette99::pick(i).to_rgba();
        chart
            .draw_series(LineSeries::new(
                line.points.iter().copied(),
                line_style(color),
            ))?
            .label(line.name.as_str())
            .legend(legend_line(color));
    }
    draw_legend(&mut chart)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_are_padded_and_never_empty() {
        let r = padded_range([0.0, 1.0]);
        assert!((r.start + 0.05).abs() < 1e-12 && (r.end - 1.05).abs() < 1e-12);
        let flat = padded_range([2.0, 2.0]);
        assert!(flat.end - flat.start >= MIN_AXIS_SPAN * 0.999);
        assert_eq!(padded_range([f64::NAN]), 0.0..1.0);
    }

    #[test]
    fn the_embedded_font_registers() {
        register_fonts().unwrap();
    }
}
