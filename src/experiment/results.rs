//! One row per run: `results.csv` (the documented columns) and `results.json` (those and more).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::analysis::bag::mean_and_sample_std;

/// The columns of `results.csv`, in order (`docs/experiment.md`).
pub const CSV_COLUMNS: [&str; 17] = [
    "curvature_per_r",
    "frequency_hz",
    "terrain_model",
    "start_x_m",
    "mean_speed_m_s",
    "speed_per_cycle_mean_m_s",
    "speed_per_cycle_std_m_s",
    "cycles",
    "sinkage_mean_m",
    "robot_mass_kg",
    "max_tilt_deg",
    "yaw_change_deg",
    "travel_direction_deg",
    "bed_edge_s",
    "wall_time_s",
    "wall_time_per_sim_s",
    "status",
];

/// `status` of a run that went through.
pub const STATUS_OK: &str = "ok";

/// What one run measured. Absent values (a failed run, no sand surface for sinkage) are
/// `None`: empty in the CSV, `null` in the JSON.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct RunResult {
    /// The run's name (`k<curvature>_f<frequency>hz_<model>`, with `_start<i>` when there
    /// are several starts), its bag's folder name.
    pub run: String,
    /// Leg curvature (1/R).
    pub curvature_per_r: f64,
    /// Gait frequency (Hz).
    pub frequency_hz: f64,
    /// `mpm` or `rft`.
    pub terrain_model: String,
    /// Where the robot started along x (m).
    #[serde(default)]
    pub start_x_m: f64,
    /// Body displacement along x over the measured window (`cycles + 1/2` gait cycles from the
    /// measurement's start to the end of the run) over its duration (m/s).
    pub mean_speed_m_s: Option<f64>,
    /// Mean of the speeds of the measured gait cycles (m/s).
    pub speed_per_cycle_mean_m_s: Option<f64>,
    /// Their population standard deviation (m/s).
    pub speed_per_cycle_std_m_s: Option<f64>,
    /// Complete gait cycles measured.
    pub cycles: Option<usize>,
    /// Mean depth of the deepest leg point below the sand level over the window (m).
    pub sinkage_mean_m: Option<f64>,
    /// Robot mass as simulated (kg, the rapier bodies' masses).
    pub robot_mass_kg: Option<f64>,
    /// Largest tilt of the body from upright over the whole run, settling included (deg).
    pub max_tilt_deg: Option<f64>,
    /// Wall time of the simulation (s).
    pub wall_time_s: Option<f64>,
    /// Wall time per simulated second (s/s).
    pub wall_time_per_sim_s: Option<f64>,
    /// `ok`, or why the run failed.
    pub status: String,
    /// The speed of each measured cycle (m/s).
    pub speed_per_cycle_m_s: Vec<f64>,
    /// Simulated time (s).
    pub sim_time_s: Option<f64>,
    /// Body position at the end (m, odom).
    pub final_position_m: Option<[f64; 3]>,
    /// Heading change over the run (deg; the body's x axis at the end, a snapshot of a
    /// heading that swings within each gait cycle).
    pub yaw_change_deg: Option<f64>,
    /// Direction of the body's horizontal displacement over the run, counter-clockwise from
    /// +x (deg): where the robot went.
    #[serde(default)]
    pub travel_direction_deg: Option<f64>,
    /// When the robot reached a side of the sand bed (s; absent if it never did): from then on
    /// it was at or over the bed's edge, not on open sand.
    #[serde(default)]
    pub bed_edge_s: Option<f64>,
    /// Sand particles (0 without MPM sand).
    pub particles: Option<usize>,
    /// The URDF the run used.
    pub urdf: String,
    /// The run's bag folder.
    pub bag: String,
}

impl RunResult {
    /// Whether the run went through.
    pub fn is_ok(&self) -> bool {
        self.status == STATUS_OK
    }

    /// The CSV cells of this row, in [`CSV_COLUMNS`] order.
    fn csv_cells(&self) -> [String; 17] {
        [
            format!("{}", self.curvature_per_r),
            format!("{}", self.frequency_hz),
            self.terrain_model.clone(),
            format!("{}", self.start_x_m),
            opt(self.mean_speed_m_s),
            opt(self.speed_per_cycle_mean_m_s),
            opt(self.speed_per_cycle_std_m_s),
            self.cycles.map_or(String::new(), |n| n.to_string()),
            opt(self.sinkage_mean_m),
            opt(self.robot_mass_kg),
            opt(self.max_tilt_deg),
            opt(self.yaw_change_deg),
            opt(self.travel_direction_deg),
            opt(self.bed_edge_s),
            opt(self.wall_time_s),
            opt(self.wall_time_per_sim_s),
            self.status.clone(),
        ]
    }
}

/// An optional number as a CSV cell: empty when absent.
fn opt(value: Option<f64>) -> String {
    value.map_or(String::new(), |v| format!("{v}"))
}

/// One CSV cell: quoted (with quotes doubled) when it holds a comma, a quote or a line break
/// (RFC 4180).
fn csv_cell(text: &str) -> String {
    if text.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", text.replace('"', "\"\""))
    } else {
        text.to_string()
    }
}

/// The text of `results.csv`: a header of [`CSV_COLUMNS`] and one line per run.
pub fn results_csv(runs: &[RunResult]) -> String {
    csv_table(&CSV_COLUMNS, runs.iter().map(|r| r.csv_cells().to_vec()))
}

/// A CSV table (RFC 4180): a header of `columns` and one line per row of cells.
pub(crate) fn csv_table(columns: &[&str], rows: impl IntoIterator<Item = Vec<String>>) -> String {
    let mut text = columns.join(",");
    text.push('\n');
    for row in rows {
        let cells: Vec<String> = row.iter().map(|c| csv_cell(c)).collect();
        text.push_str(&cells.join(","));
        text.push('\n');
    }
    text
}

/// Writes [`results_csv`] to `path`.
pub fn write_results_csv(path: &Path, runs: &[RunResult]) -> std::io::Result<()> {
    std::fs::write(path, results_csv(runs))
}

/// The columns of `summary.csv`, in order (`docs/experiment.md`).
pub const SUMMARY_COLUMNS: [&str; 13] = [
    "curvature_per_r",
    "frequency_hz",
    "terrain_model",
    "starts",
    "completed",
    "speed_mean_m_s",
    "speed_std_m_s",
    "speed_standard_error_m_s",
    "sinkage_mean_m",
    "max_tilt_deg",
    "max_abs_travel_direction_deg",
    "turned_over",
    "reached_bed_edge",
];

/// A tilt beyond this (deg) puts the body's up axis below the horizon: the robot is on its
/// side or back.
pub const TURNED_OVER_TILT_DEG: f64 = 90.0;

/// One cell of the sweep (terrain model, frequency, curvature) over its starts.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CellSummary {
    /// Leg curvature (1/R).
    pub curvature_per_r: f64,
    /// Gait frequency (Hz).
    pub frequency_hz: f64,
    /// `mpm` or `rft`.
    pub terrain_model: String,
    /// Runs of the cell, one per start.
    pub starts: usize,
    /// Runs that went through and measured a speed.
    pub completed: usize,
    /// Mean over the completed runs of each run's mean per-cycle speed (m/s).
    pub speed_mean_m_s: Option<f64>,
    /// Their sample standard deviation over starts (m/s); absent below two completed runs.
    pub speed_std_m_s: Option<f64>,
    /// `speed_std_m_s / sqrt(completed)` (m/s): the noise of `speed_mean_m_s`.
    pub speed_standard_error_m_s: Option<f64>,
    /// Mean over the completed runs of each run's mean sinkage (m).
    pub sinkage_mean_m: Option<f64>,
    /// Largest tilt over the cell's runs (deg).
    pub max_tilt_deg: Option<f64>,
    /// Largest magnitude of a run's direction of travel over the cell's runs (deg): how far
    /// from straight ahead the worst start went.
    #[serde(default)]
    pub max_abs_travel_direction_deg: Option<f64>,
    /// Runs that tilted beyond [`TURNED_OVER_TILT_DEG`].
    pub turned_over: usize,
    /// Runs in which the robot reached a side of the sand bed.
    #[serde(default)]
    pub reached_bed_edge: usize,
}

impl CellSummary {
    fn csv_cells(&self) -> [String; 13] {
        [
            format!("{}", self.curvature_per_r),
            format!("{}", self.frequency_hz),
            self.terrain_model.clone(),
            self.starts.to_string(),
            self.completed.to_string(),
            opt(self.speed_mean_m_s),
            opt(self.speed_std_m_s),
            opt(self.speed_standard_error_m_s),
            opt(self.sinkage_mean_m),
            opt(self.max_tilt_deg),
            opt(self.max_abs_travel_direction_deg),
            self.turned_over.to_string(),
            self.reached_bed_edge.to_string(),
        ]
    }
}

/// The runs grouped by cell (terrain model, frequency, curvature), in the order the cells first
/// appear in `runs`.
pub fn summarize(runs: &[RunResult]) -> Vec<CellSummary> {
    let same_cell = |a: &RunResult, b: &CellSummary| {
        a.terrain_model == b.terrain_model
            && a.frequency_hz == b.frequency_hz
            && a.curvature_per_r == b.curvature_per_r
    };
    let mut cells: Vec<CellSummary> = Vec::new();
    for run in runs {
        if !cells.iter().any(|c| same_cell(run, c)) {
            cells.push(CellSummary {
                curvature_per_r: run.curvature_per_r,
                frequency_hz: run.frequency_hz,
                terrain_model: run.terrain_model.clone(),
                ..CellSummary::default()
            });
        }
    }
    for cell in &mut cells {
        let members: Vec<&RunResult> = runs.iter().filter(|r| same_cell(r, cell)).collect();
        let measured: Vec<&RunResult> = members
            .iter()
            .copied()
            .filter(|r| r.is_ok() && r.speed_per_cycle_mean_m_s.is_some())
            .collect();
        let speeds: Vec<f64> = measured
            .iter()
            .filter_map(|r| r.speed_per_cycle_mean_m_s)
            .collect();
        let sinkages: Vec<f64> = measured.iter().filter_map(|r| r.sinkage_mean_m).collect();
        let tilts = members.iter().filter_map(|r| r.max_tilt_deg);
        cell.starts = members.len();
        cell.completed = measured.len();
        let speed = mean_and_sample_std(&speeds);
        cell.speed_mean_m_s = speed.map(|(mean, _)| mean);
        cell.speed_std_m_s = speed.and_then(|(_, std)| std);
        cell.speed_standard_error_m_s =
            cell.speed_std_m_s.map(|s| s / (speeds.len() as f64).sqrt());
        cell.sinkage_mean_m = mean_and_sample_std(&sinkages).map(|(mean, _)| mean);
        cell.max_tilt_deg = tilts.clone().reduce(f64::max);
        cell.max_abs_travel_direction_deg = members
            .iter()
            .filter_map(|r| r.travel_direction_deg.map(f64::abs))
            .reduce(f64::max);
        cell.turned_over = tilts.filter(|&t| t > TURNED_OVER_TILT_DEG).count();
        cell.reached_bed_edge = members.iter().filter(|r| r.bed_edge_s.is_some()).count();
    }
    cells
}

/// The text of `summary.csv`: a header of [`SUMMARY_COLUMNS`] and one line per cell.
pub fn summary_csv(cells: &[CellSummary]) -> String {
    csv_table(
        &SUMMARY_COLUMNS,
        cells.iter().map(|c| c.csv_cells().to_vec()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row() -> RunResult {
        RunResult {
            run: "k-0.5_f2hz_mpm".into(),
            curvature_per_r: -0.5,
            frequency_hz: 2.0,
            terrain_model: "mpm".into(),
            mean_speed_m_s: Some(0.125),
            speed_per_cycle_mean_m_s: Some(0.12),
            speed_per_cycle_std_m_s: Some(0.01),
            cycles: Some(4),
            sinkage_mean_m: None,
            robot_mass_kg: Some(0.085),
            max_tilt_deg: Some(12.5),
            yaw_change_deg: Some(-7.5),
            travel_direction_deg: Some(2.5),
            bed_edge_s: Some(1.25),
            wall_time_s: Some(200.0),
            wall_time_per_sim_s: Some(80.0),
            status: STATUS_OK.into(),
            ..RunResult::default()
        }
    }

    #[test]
    fn csv_has_the_documented_columns_and_empty_cells_for_missing_values() {
        let failed = RunResult {
            curvature_per_r: 1.0,
            frequency_hz: 1.0,
            terrain_model: "rft".into(),
            status: "--set terrain.model=rft: unknown field `terrain`, expected \"x\"\nmore".into(),
            ..RunResult::default()
        };
        let text = results_csv(&[row(), failed]);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], CSV_COLUMNS.join(","));
        assert_eq!(
            lines[1],
            "-0.5,2,mpm,0,0.125,0.12,0.01,4,,0.085,12.5,-7.5,2.5,1.25,200,80,ok"
        );
        // The failure's message is one quoted cell, quotes doubled, line break kept.
        assert_eq!(
            lines[2],
            concat!(
                "1,1,rft,0,,,,,,,,,,,,,",
                "\"--set terrain.model=rft: unknown field `terrain`, expected \"\"x\"\""
            )
        );
        assert_eq!(lines[3], "more\"");
        assert_eq!(text.matches('\n').count(), 4);
        assert_eq!(lines[1].split(',').count(), CSV_COLUMNS.len());
    }

    #[test]
    fn results_written_before_the_direction_and_bed_edge_columns_still_read() {
        let mut old = serde_json::to_value(row()).unwrap();
        for key in ["travel_direction_deg", "bed_edge_s"] {
            old.as_object_mut().unwrap().remove(key);
        }
        let read: RunResult = serde_json::from_value(old).unwrap();
        assert_eq!((read.travel_direction_deg, read.bed_edge_s), (None, None));
        assert_eq!(read.max_tilt_deg, row().max_tilt_deg);
    }

    #[test]
    fn cells_are_quoted_only_when_needed() {
        assert_eq!(csv_cell("ok"), "ok");
        assert_eq!(csv_cell("a,b"), "\"a,b\"");
        assert_eq!(csv_cell("say \"hi\""), "\"say \"\"hi\"\"\"");
    }

    #[test]
    fn the_csv_file_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("results.csv");
        write_results_csv(&path, &[row()]).unwrap();
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            results_csv(&[row()])
        );
    }

    #[test]
    fn cells_summarize_their_starts() {
        let start = |k: f64, v: Option<f64>, tilt: f64, status: &str| RunResult {
            curvature_per_r: k,
            speed_per_cycle_mean_m_s: v,
            sinkage_mean_m: v.map(|v| v / 10.0),
            max_tilt_deg: Some(tilt),
            travel_direction_deg: Some(if tilt > 25.0 { -tilt / 2.0 } else { tilt / 4.0 }),
            bed_edge_s: (tilt > 25.0).then_some(1.0),
            status: status.into(),
            ..row()
        };
        let runs = [
            start(1.0, Some(0.1), 10.0, STATUS_OK),
            start(-1.0, Some(0.0), 120.0, STATUS_OK),
            start(1.0, Some(0.2), 20.0, STATUS_OK),
            start(1.0, None, 95.0, "blew up"),
            start(1.0, Some(0.3), 30.0, STATUS_OK),
        ];
        let cells = summarize(&runs);
        assert_eq!(cells.len(), 2);
        let c = &cells[0];
        assert_eq!((c.curvature_per_r, c.starts, c.completed), (1.0, 4, 3));
        assert!((c.speed_mean_m_s.unwrap() - 0.2).abs() < 1e-12);
        // Sample standard deviation of 0.1, 0.2, 0.3 is 0.1; over sqrt(3) starts.
        assert!((c.speed_std_m_s.unwrap() - 0.1).abs() < 1e-12);
        assert!((c.speed_standard_error_m_s.unwrap() - 0.1 / 3f64.sqrt()).abs() < 1e-12);
        assert!((c.sinkage_mean_m.unwrap() - 0.02).abs() < 1e-12);
        // The failed run's tilt counts: it turned over before it failed.
        assert_eq!((c.max_tilt_deg, c.turned_over), (Some(95.0), 1));
        // The largest direction off +x in either sense: -47.5 deg, the failed run's.
        assert_eq!(c.max_abs_travel_direction_deg, Some(47.5));
        assert_eq!(c.reached_bed_edge, 2);
        let single = &cells[1];
        assert_eq!(
            (single.starts, single.completed, single.turned_over),
            (1, 1, 1)
        );
        assert_eq!(single.speed_std_m_s, None);
        let text = summary_csv(&cells);
        assert_eq!(text.lines().next().unwrap(), SUMMARY_COLUMNS.join(","));
        assert_eq!(
            text.lines().nth(2).unwrap(),
            "-1,2,mpm,1,1,0,,,0,120,60,1,1"
        );
    }
}
