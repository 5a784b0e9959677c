//! [`BagReader`]: reads rosbag2 MCAP bags (this crate's and other tools').

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::chunks::messages;
use super::metadata::{MetadataFileIn, SERIALIZATION_FORMAT, STORAGE_IDENTIFIER};
use super::{BagError, TopicInfo, METADATA_FILE_NAME};
use crate::msgs::{from_cdr, MessageType, RosMessage};

/// Extension of MCAP files.
const MCAP_EXTENSION: &str = "mcap";

/// (topic, message count) pairs, sorted by topic.
type TopicCounts = Vec<(String, u64)>;

/// The messages of one topic.
struct TopicData {
    /// Full type name (`pkg/msg/Name`); empty for a channel without schema.
    type_name: String,
    /// Message encoding of its channels (`cdr` for ROS 2).
    encoding: String,
    /// (log time in ns, encoded message), in log-time order.
    messages: Vec<(u64, Vec<u8>)>,
}

/// A bag read whole into memory: every message of every topic, by topic.
pub struct BagReader {
    /// What was opened (bag directory or `.mcap` file).
    path: PathBuf,
    /// The MCAP files read, in order.
    files: Vec<PathBuf>,
    topics: Vec<TopicInfo>,
    data: BTreeMap<String, TopicData>,
    /// Per-topic message counts from `metadata.yaml`, sorted by topic.
    metadata_counts: Option<TopicCounts>,
    /// What was wrong but did not stop the read.
    warnings: Vec<String>,
}

impl BagReader {
    /// Opens a bag directory (its `metadata.yaml` and the `.mcap` files it lists; without
    /// `metadata.yaml`, the single `.mcap` in it), a bare `.mcap` file, or a bag's
    /// `metadata.yaml`. Reads every message into memory.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let meta = std::fs::metadata(path).map_err(|e| BagError::io(path, e))?;
        let dir = if meta.is_dir() {
            Some(path.to_path_buf())
        } else if path.file_name().is_some_and(|n| n == METADATA_FILE_NAME) {
            path.parent().map(Path::to_path_buf)
        } else {
            None
        };
        let (files, metadata_counts) = match &dir {
            None => (vec![path.to_path_buf()], None),
            Some(dir) => {
                let metadata_path = dir.join(METADATA_FILE_NAME);
                if metadata_path.exists() {
                    let (files, counts) = read_metadata(&metadata_path, dir)?;
                    (files, Some(counts))
                } else {
                    (vec![single_mcap(dir)?], None)
                }
            }
        };
        let mut data: BTreeMap<String, TopicData> = BTreeMap::new();
        let mut warnings = Vec::new();
        for file in &files {
            warnings.extend(read_mcap(file, &mut data)?);
        }
        for topic in data.values_mut() {
            // Stable: messages with equal log times keep their file order.
            topic.messages.sort_by_key(|(time, _)| *time);
        }
        let topics = data
            .iter()
            .map(|(name, d)| TopicInfo {
                name: name.clone(),
                type_name: d.type_name.clone(),
                message_count: d.messages.len() as u64,
            })
            .collect();
        Ok(Self {
            path: path.to_path_buf(),
            files,
            topics,
            data,
            metadata_counts,
            warnings,
        })
    }

    /// What was wrong with the bag but did not stop it being read (an unfinished MCAP file).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// What was opened.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The MCAP files read, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }

    /// Topics of the MCAP file(s) with the number of messages actually in them, sorted by
    /// name.
    pub fn topics(&self) -> &[TopicInfo] {
        &self.topics
    }

    /// Per-topic `message_count` from `metadata.yaml`, sorted by topic; `None` without one.
    pub fn metadata_counts(&self) -> Option<Vec<(String, u64)>> {
        self.metadata_counts.clone()
    }

    /// Log time of the earliest message (ns); `None` if the bag has no message.
    pub fn start_time_ns(&self) -> Option<u64> {
        self.data
            .values()
            .filter_map(|d| d.messages.first().map(|(t, _)| *t))
            .min()
    }

    /// Log time of the latest message (ns); `None` if the bag has no message.
    pub fn end_time_ns(&self) -> Option<u64> {
        self.data
            .values()
            .filter_map(|d| d.messages.last().map(|(t, _)| *t))
            .max()
    }

    /// All messages of `topic` decoded as `M`, in log-time order, with their log time (ns).
    pub fn read<M: RosMessage>(&self, topic: &str) -> Result<Vec<(u64, M)>, BagError> {
        let data = self.data.get(topic).ok_or_else(|| BagError::TopicAbsent {
            path: self.path.clone(),
            topic: topic.into(),
            present: self.data.keys().cloned().collect(),
        })?;
        if data.encoding != SERIALIZATION_FORMAT {
            return Err(BagError::Encoding {
                path: self.path.clone(),
                topic: topic.into(),
                encoding: data.encoding.clone(),
            });
        }
        let expected = M::TYPE.type_name();
        if data.type_name != expected {
            return Err(BagError::TypeMismatch {
                path: self.path.clone(),
                topic: topic.into(),
                bag_type: data.type_name.clone(),
                expected,
            });
        }
        data.messages
            .iter()
            .enumerate()
            .map(|(index, (time, bytes))| {
                from_cdr::<M>(bytes)
                    .map(|m| (*time, m))
                    .map_err(|source| BagError::Decode {
                        path: self.path.clone(),
                        topic: topic.into(),
                        index,
                        cause: source,
                    })
            })
            .collect()
    }

    /// Topics whose type is `ty` (e.g. all `WrenchStamped` topics), sorted by name.
    pub fn topics_of_type(&self, ty: &MessageType) -> Vec<String> {
        let wanted = ty.type_name();
        self.topics
            .iter()
            .filter(|t| t.type_name == wanted)
            .map(|t| t.name.clone())
            .collect()
    }
}

/// `pkg/msg/Name` for a schema name with or without `/msg/`.
pub(super) fn full_type_name(schema_name: &str) -> String {
    match schema_name.split('/').collect::<Vec<_>>()[..] {
        [package, name] => format!("{package}/msg/{name}"),
        _ => schema_name.to_string(),
    }
}

/// The MCAP files `metadata.yaml` lists and its per-topic counts (sorted by topic).
fn read_metadata(
    metadata_path: &Path,
    dir: &Path,
) -> Result<(Vec<PathBuf>, TopicCounts), BagError> {
    let bad = |message: String| BagError::Metadata {
        path: metadata_path.to_path_buf(),
        message,
    };
    let text =
        std::fs::read_to_string(metadata_path).map_err(|e| BagError::io(metadata_path, e))?;
    let parsed: MetadataFileIn = serde_yaml_ng::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let info = parsed.rosbag2_bagfile_information;
    if !info.storage_identifier.is_empty() && info.storage_identifier != STORAGE_IDENTIFIER {
        return Err(bad(format!(
            "storage_identifier {:?}: only MCAP bags are read",
            info.storage_identifier
        )));
    }
    if !info.compression_mode.is_empty() && !info.compression_mode.eq_ignore_ascii_case("none") {
        return Err(bad(format!(
            "compression_mode {:?} ({}): only uncompressed bags (MCAP chunk compression is fine) are read",
            info.compression_mode, info.compression_format
        )));
    }
    // Older rosbag2 versions wrote paths with the bag directory in front: keep the file name.
    let files = info
        .relative_file_paths
        .iter()
        .map(|p| {
            Path::new(p)
                .file_name()
                .map(|name| dir.join(name))
                .ok_or_else(|| bad(format!("relative_file_paths entry {p:?} names no file")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    if files.is_empty() {
        return Err(bad("relative_file_paths is empty".into()));
    }
    let mut counts: TopicCounts = info
        .topics_with_message_count
        .into_iter()
        .map(|t| (t.topic_metadata.name, t.message_count))
        .collect();
    counts.sort();
    Ok((files, counts))
}

/// The one `.mcap` file of a directory without `metadata.yaml`.
pub(super) fn single_mcap(dir: &Path) -> Result<PathBuf, BagError> {
    let mut found = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| BagError::io(dir, e))? {
        let path = entry.map_err(|e| BagError::io(dir, e))?.path();
        if path.is_file() && path.extension().is_some_and(|e| e == MCAP_EXTENSION) {
            found.push(path);
        }
    }
    found.sort();
    match found.len() {
        0 => Err(BagError::NoMcap {
            path: dir.to_path_buf(),
        }),
        1 => Ok(found.remove(0)),
        _ => Err(BagError::SeveralMcap {
            path: dir.to_path_buf(),
            files: found
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect(),
        }),
    }
}

/// Adds every message and channel of the MCAP file `path` to `data`. A file that was never
/// finished (its writer killed: no summary, no closing magic) gives the messages of its
/// complete chunks, and `Some` with what was left unread.
fn read_mcap(
    path: &Path,
    data: &mut BTreeMap<String, TopicData>,
) -> Result<Option<String>, BagError> {
    let bytes = std::fs::read(path).map_err(|e| BagError::io(path, e))?;
    if bytes.starts_with(mcap::MAGIC) && !bytes.ends_with(mcap::MAGIC) {
        return read_unfinished_mcap(path, &bytes, data).map(Some);
    }
    for message in messages(&bytes, false) {
        let message = message.map_err(|e| BagError::mcap(path, e))?;
        topic_of_channel(data, &message.channel, path)?
            .messages
            .push((message.log_time, message.data.into_owned()));
    }
    // Channels without messages are only in the summary.
    if let Some(summary) = mcap::Summary::read(&bytes).map_err(|e| BagError::mcap(path, e))? {
        let mut channels: Vec<_> = summary.channels.values().collect();
        channels.sort_by_key(|c| c.id);
        for channel in channels {
            topic_of_channel(data, channel, path)?;
        }
    }
    Ok(None)
}

/// The messages of an unfinished MCAP file, read from its start up to the first record that
/// is cut off (the chunk being written when its writer died) or damaged; says what was left
/// unread and why.
fn read_unfinished_mcap(
    path: &Path,
    bytes: &[u8],
    data: &mut BTreeMap<String, TopicData>,
) -> Result<String, BagError> {
    let mut read = 0u64;
    for message in messages(bytes, true) {
        let message = match message {
            Ok(message) => message,
            Err(error) => {
                return Ok(format!(
                    "{} is unfinished (its writer was killed?): read {read} messages from its \
                     complete chunks, the rest of the file is cut off or damaged ({error}); \
                     `sandstep bag reindex` finishes it",
                    path.display()
                ))
            }
        };
        topic_of_channel(data, &message.channel, path)?
            .messages
            .push((message.log_time, message.data.into_owned()));
        read += 1;
    }
    Ok(format!(
        "{} is unfinished (no summary or closing magic): read {read} messages; `sandstep bag \
         reindex` finishes it",
        path.display()
    ))
}

/// The entry of `channel`'s topic in `data`, added if new; an error if the topic has another
/// type in an earlier channel.
fn topic_of_channel<'a>(
    data: &'a mut BTreeMap<String, TopicData>,
    channel: &mcap::Channel,
    path: &Path,
) -> Result<&'a mut TopicData, BagError> {
    let type_name = channel
        .schema
        .as_ref()
        .map(|s| full_type_name(&s.name))
        .unwrap_or_default();
    let topic = data
        .entry(channel.topic.clone())
        .or_insert_with(|| TopicData {
            type_name: type_name.clone(),
            encoding: channel.message_encoding.clone(),
            messages: Vec::new(),
        });
    if topic.type_name != type_name {
        return Err(BagError::ChannelTypeConflict {
            path: path.to_path_buf(),
            topic: channel.topic.clone(),
            first: topic.type_name.clone(),
            second: type_name,
        });
    }
    Ok(topic)
}
