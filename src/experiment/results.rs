//! One row per run: `results.csv` (the documented columns) and `results.json` (those and more).

use std::path::Path;

use serde::{Deserialize, Serialize};

/// The columns of `results.csv`, in order (`docs/experiment.md`).
pub const CSV_COLUMNS: [&str; 13] = [
    "curvature_per_r",
    "frequency_hz",
    "terrain_model",
    "mean_speed_m_s",
    "speed_per_cycle_mean_m_s",
    "speed_per_cycle_std_m_s",
    "cycles",
    "sinkage_mean_m",
    "robot_mass_kg",
    "max_tilt_deg",
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
    /// The run's name (`k<curvature>_f<frequency>hz_<model>`), its bag's folder name.
    pub run: String,
    /// Leg curvature (1/R).
    pub curvature_per_r: f64,
    /// Gait frequency (Hz).
    pub frequency_hz: f64,
    /// `mpm` or `rft`.
    pub terrain_model: String,
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
    /// Heading change over the run (deg).
    pub yaw_change_deg: Option<f64>,
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
    fn csv_cells(&self) -> [String; 13] {
        let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v}"));
        [
            format!("{}", self.curvature_per_r),
            format!("{}", self.frequency_hz),
            self.terrain_model.clone(),
            opt(self.mean_speed_m_s),
            opt(self.speed_per_cycle_mean_m_s),
            opt(self.speed_per_cycle_std_m_s),
            self.cycles.map_or(String::new(), |n| n.to_string()),
            opt(self.sinkage_mean_m),
            opt(self.robot_mass_kg),
            opt(self.max_tilt_deg),
            opt(self.wall_time_s),
            opt(self.wall_time_per_sim_s),
            self.status.clone(),
        ]
    }
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
            "-0.5,2,mpm,0.125,0.12,0.01,4,,0.085,12.5,200,80,ok"
        );
        // The failure's message is one quoted cell, quotes doubled, line break kept.
        assert_eq!(
            lines[2],
            "1,1,rft,,,,,,,,,,\"--set terrain.model=rft: unknown field `terrain`, expected \"\"x\"\""
        );
        assert_eq!(lines[3], "more\"");
        assert_eq!(text.matches('\n').count(), 4);
        assert_eq!(lines[1].split(',').count(), CSV_COLUMNS.len());
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
}
