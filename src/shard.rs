//! Studies as independent jobs (`docs/cluster.md`): the runs of an experiment, or the settings
//! of a sweep, spread over the tasks of a batch scheduler's job array.
//!
//! Each task runs one [`Selection`] of the study's units into a shared output folder, where
//! every unit leaves a [`UnitRecord`] of its own (written whole, [`crate::files`]); a last job
//! merges the records, in the study's order, into the results a single process writes.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// A merge names at most this many missing units (and says how many there are).
const MISSING_NAMES_SHOWN: usize = 8;

/// Shard `index` of `count`, both from 1 as in `--shard 2/8` and Slurm's array task ids: unit
/// `i` (from 0, in the study's order) belongs to shard `i % count + 1`. Round robin, so every
/// shard gets a share of each frequency and model rather than all of the slow ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    index: usize,
    count: usize,
}

/// Text that is not `I/N` with `1 <= I <= N`.
#[derive(thiserror::Error, Debug, Clone, PartialEq, Eq)]
#[error("'{0}': a shard is I/N with 1 <= I <= N, e.g. 2/8")]
pub struct BadShard(pub String);

impl FromStr for Shard {
    type Err = BadShard;

    fn from_str(text: &str) -> Result<Self, BadShard> {
        let bad = || BadShard(text.to_string());
        let (index, count) = text.split_once('/').ok_or_else(bad)?;
        let index: usize = index.trim().parse().map_err(|_| bad())?;
        let count: usize = count.trim().parse().map_err(|_| bad())?;
        Shard::new(index, count).ok_or_else(bad)
    }
}

impl Shard {
    /// Shard `index` of `count`, if `1 <= index <= count`.
    pub fn new(index: usize, count: usize) -> Option<Shard> {
        (1..=count)
            .contains(&index)
            .then_some(Shard { index, count })
    }

    /// Whether unit `unit` (from 0) is this shard's.
    pub fn holds(&self, unit: usize) -> bool {
        unit % self.count + 1 == self.index
    }
}

/// Which of a study's units one process runs.
#[derive(Clone, Debug, Default, PartialEq)]
pub enum Selection {
    /// Every unit; the process also writes the study's results.
    #[default]
    All,
    /// One shard of the units.
    Shard(Shard),
    /// The units of these names (`--run NAME`).
    Named(Vec<String>),
}

impl Selection {
    /// Whether every unit is run by this process.
    pub fn is_all(&self) -> bool {
        *self == Selection::All
    }

    /// Which of the study's units (`names`, in order) are selected; an error names a
    /// `--run` that is not one of them.
    pub fn pick(&self, names: &[&str]) -> Result<Vec<bool>, UnknownRun> {
        match self {
            Selection::All => Ok(vec![true; names.len()]),
            Selection::Shard(shard) => Ok((0..names.len()).map(|i| shard.holds(i)).collect()),
            Selection::Named(wanted) => {
                if let Some(unknown) = wanted.iter().find(|w| !names.contains(&w.as_str())) {
                    return Err(UnknownRun {
                        name: unknown.clone(),
                        count: names.len(),
                    });
                }
                Ok(names
                    .iter()
                    .map(|n| wanted.iter().any(|w| w == n))
                    .collect())
            }
        }
    }
}

/// A `--run NAME` that names none of the study's runs.
#[derive(thiserror::Error, Debug, Clone, PartialEq, Eq)]
#[error("--run {name}: there is no such run (`--list` prints the {count} runs)")]
pub struct UnknownRun {
    pub name: String,
    pub count: usize,
}

/// What one unit leaves in the shared folder.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct UnitRecord<C, R> {
    /// The study's settings, defaults filled in: a merge refuses a record of other settings.
    pub config: C,
    /// Local time the unit started, `YYYY-mm-dd HH:MM:SS`.
    pub started: String,
    /// Worker threads of its simulations.
    pub threads: usize,
    /// What it measured.
    pub result: R,
}

/// Local time now, `YYYY-mm-dd HH:MM:SS`: when a unit or a study started.
pub fn local_time_now() -> String {
    chrono::Local::now().format("%Y-%m-%d %H:%M:%S").to_string()
}

/// Writes `record` to `path` (pretty JSON, whole or not at all), creating its folder.
pub fn write_record<C: Serialize, R: Serialize>(
    path: &Path,
    record: &UnitRecord<C, R>,
) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let json = serde_json::to_string_pretty(record).expect("plain data") + "\n";
    crate::files::write_atomically(path, json.as_bytes())
}

/// Why records could not be merged.
#[derive(thiserror::Error, Debug)]
pub enum MergeError {
    #[error(
        "{missing} of {total} {what} {} no result in {}: {names} (run them with \
         --run NAME, or run again the shards that hold them)",
        if *missing == 1 { "has" } else { "have" },
        folder.display()
    )]
    Missing {
        missing: usize,
        total: usize,
        what: &'static str,
        folder: PathBuf,
        names: String,
    },
    #[error("{}: {message}", path.display())]
    Unreadable { path: PathBuf, message: String },
    #[error(
        "{} holds a result of other settings ({differences}): the shards, a resume and the \
         merge of a study must be given the same file and --set options",
        path.display()
    )]
    OtherSettings { path: PathBuf, differences: String },
}

/// The record at `path`, if there is one; an error if it cannot be read or holds a study
/// with other settings than `config`.
pub fn read_record<C, R>(path: &Path, config: &C) -> Result<Option<UnitRecord<C, R>>, MergeError>
where
    C: Serialize + DeserializeOwned + PartialEq,
    R: DeserializeOwned,
{
    let unreadable = |message: String| MergeError::Unreadable {
        path: path.to_path_buf(),
        message,
    };
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(unreadable(e.to_string())),
    };
    let record: UnitRecord<C, R> = serde_json::from_str(&text)
        .map_err(|e| unreadable(format!("not a sandstep result record: {e}")))?;
    if record.config != *config {
        return Err(MergeError::OtherSettings {
            path: path.to_path_buf(),
            differences: differences(&record.config, config),
        });
    }
    Ok(Some(record))
}

/// The settings whose values differ, `key: recorded X, now Y` (top-level keys of the JSON).
fn differences<C: Serialize>(recorded: &C, now: &C) -> String {
    let json = |c: &C| serde_json::to_value(c).expect("plain data");
    let (recorded, now) = (json(recorded), json(now));
    let (Some(recorded_keys), Some(now_keys)) = (recorded.as_object(), now.as_object()) else {
        return format!("recorded {recorded}; now {now}");
    };
    let null = serde_json::Value::Null;
    let mut keys: Vec<&String> = recorded_keys.keys().chain(now_keys.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter(|k| recorded_keys.get(*k) != now_keys.get(*k))
        .map(|k| {
            let was = recorded_keys.get(k).unwrap_or(&null);
            let is = now_keys.get(k).unwrap_or(&null);
            format!("{k}: recorded {was}, now {is}")
        })
        .collect::<Vec<_>>()
        .join("; ")
}

/// The records of every unit, in the study's order: `units` are (name, record path). An
/// error names the units without one (the first [`MISSING_NAMES_SHOWN`]).
pub fn read_all_records<C, R>(
    folder: &Path,
    what: &'static str,
    units: &[(String, PathBuf)],
    config: &C,
) -> Result<Vec<UnitRecord<C, R>>, MergeError>
where
    C: Serialize + DeserializeOwned + PartialEq,
    R: DeserializeOwned,
{
    let mut records = Vec::with_capacity(units.len());
    let mut missing = Vec::new();
    for (name, path) in units {
        match read_record(path, config)? {
            Some(record) => records.push(record),
            None => missing.push(name.as_str()),
        }
    }
    if missing.is_empty() {
        return Ok(records);
    }
    let mut names = missing[..missing.len().min(MISSING_NAMES_SHOWN)].join(", ");
    if missing.len() > MISSING_NAMES_SHOWN {
        names.push_str(", ...");
    }
    Err(MergeError::Missing {
        missing: missing.len(),
        total: units.len(),
        what,
        folder: folder.to_path_buf(),
        names,
    })
}

/// The earliest of the records' start times (they sort as text).
pub fn earliest_start<C, R>(records: &[UnitRecord<C, R>]) -> String {
    records
        .iter()
        .map(|r| r.started.as_str())
        .min()
        .unwrap_or_default()
        .to_string()
}

/// The most worker threads any record's unit ran on.
pub fn most_threads<C, R>(records: &[UnitRecord<C, R>]) -> usize {
    records.iter().map(|r| r.threads).max().unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_parse_from_one_and_split_round_robin() {
        let shard: Shard = "2/3".parse().unwrap();
        assert_eq!(Some(shard), Shard::new(2, 3));
        assert_eq!(Shard::new(0, 0), None);
        let held: Vec<usize> = (0..7).filter(|&i| shard.holds(i)).collect();
        assert_eq!(held, [1, 4]);
        // Every unit is in exactly one shard.
        for unit in 0..10 {
            let owners = (1..=3)
                .filter(|&i| Shard::new(i, 3).unwrap().holds(unit))
                .count();
            assert_eq!(owners, 1);
        }
        for bad in ["0/2", "3/2", "2", "a/2", "1/0", ""] {
            let error = bad.parse::<Shard>().unwrap_err().to_string();
            assert!(error.contains("I/N"), "{bad}: {error}");
        }
    }

    #[test]
    fn named_selections_pick_by_name_and_refuse_unknown_names() {
        let names = ["a", "b", "c"];
        let pick = Selection::Named(vec!["c".into(), "a".into()]).pick(&names);
        assert_eq!(pick.unwrap(), [true, false, true]);
        let error = Selection::Named(vec!["d".into()]).pick(&names).unwrap_err();
        let message = "--run d: there is no such run (`--list` prints the 3 runs)";
        assert_eq!(error.to_string(), message);
        assert_eq!(Selection::All.pick(&names).unwrap(), [true; 3]);
    }

    #[test]
    fn records_merge_in_order_and_refuse_missing_units_and_other_settings() {
        let dir = tempfile::tempdir().unwrap();
        let path = |name: &str| dir.path().join("runs").join(format!("{name}.json"));
        let units: Vec<(String, PathBuf)> = ["a", "b"]
            .iter()
            .map(|n| (n.to_string(), path(n)))
            .collect();
        let record = |started: &str, threads, result: f64| UnitRecord {
            config: "settings".to_string(),
            started: started.into(),
            threads,
            result,
        };
        write_record(&path("b"), &record("2026-12-07 10:00:00", 2, 2.0)).unwrap();
        let missing =
            read_all_records::<String, f64>(dir.path(), "runs", &units, &"settings".into())
                .unwrap_err()
                .to_string();
        assert!(missing.starts_with("1 of 2 runs has no result") && missing.contains(": a ("));

        write_record(&path("a"), &record("2026-12-07 11:00:00", 1, 1.0)).unwrap();
        let all: Vec<UnitRecord<String, f64>> =
            read_all_records(dir.path(), "runs", &units, &"settings".into()).unwrap();
        assert_eq!(all.iter().map(|r| r.result).collect::<Vec<_>>(), [1.0, 2.0]);
        assert_eq!(earliest_start(&all), "2026-12-07 10:00:00");
        assert_eq!(most_threads(&all), 2);

        let other = read_all_records::<String, f64>(dir.path(), "runs", &units, &"new".into())
            .unwrap_err()
            .to_string();
        assert!(
            other.contains("a.json holds a result of other settings"),
            "{other}"
        );
        use serde_json::json;
        let changed = differences(&json!({"a": 1, "b": 2}), &json!({"a": 1, "b": 3, "c": 4}));
        assert_eq!(changed, "b: recorded 2, now 3; c: recorded null, now 4");
        std::fs::write(path("a"), "{").unwrap();
        let broken = read_record::<String, f64>(&path("a"), &"settings".into()).unwrap_err();
        assert!(
            broken.to_string().contains("not a sandstep result record"),
            "{broken}"
        );
    }
}
