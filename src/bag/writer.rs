//! [`BagWriter`]: records messages into a rosbag2 directory with one MCAP file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use super::metadata::{bag_metadata, BagMetadata, MetadataFile, TopicRecord, SERIALIZATION_FORMAT};
use super::{type_description_hash, BagError, Durability, TopicInfo, METADATA_FILE_NAME};
use crate::msgs::{to_cdr, MessageType, RosMessage};

/// MCAP profile of ROS 2 bags (readers such as `rosbags` refuse files without it).
const MCAP_PROFILE: &str = "ros2";
/// Schema encoding of `.msg` definitions with their dependencies.
pub(super) const SCHEMA_ENCODING: &str = "ros2msg";
/// Channel metadata key of the offered QoS profiles (YAML).
pub(super) const QOS_METADATA_KEY: &str = "offered_qos_profiles";
/// Channel metadata key of the RIHS01 type hash.
pub(super) const TYPE_HASH_METADATA_KEY: &str = "topic_type_hash";
/// Name of the MCAP metadata record in which rosbag2 repeats `metadata.yaml`.
const ROSBAG2_METADATA_RECORD: &str = "rosbag2";
/// Key of the bag metadata (YAML, without the top-level key) in that record.
const SERIALIZED_METADATA_KEY: &str = "serialized_metadata";
/// zstd worker threads: 0 compresses each chunk (1 MiB) on the writing thread instead of
/// starting one thread per physical core next to the simulation's own.
const COMPRESSION_THREADS: u32 = 0;
/// Longest wall time a written message waits in an open chunk: the chunk is then closed and
/// flushed to the file, so a killed process (SIGKILL, the out-of-memory killer) loses at most
/// this much of its recording (`sandstep bag reindex` finishes what is left).
const CHUNK_FLUSH_INTERVAL: Duration = Duration::from_secs(1);
/// Bytes a CDR message has at least: the encapsulation header.
const CDR_HEADER_LEN: usize = 4;
/// First two bytes of the encapsulation header: plain CDR, big- or little-endian.
const CDR_ENCAPSULATIONS: [[u8; 2]; 2] = [[0x00, 0x00], [0x00, 0x01]];

/// A topic declared in the bag.
struct Topic {
    ty: &'static MessageType,
    durability: Durability,
    channel_id: u16,
    /// Messages written.
    message_count: u64,
}

/// Where a finished bag is and what it holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct BagInfo {
    /// The bag directory.
    pub dir: PathBuf,
    /// The MCAP file inside it.
    pub mcap_path: PathBuf,
    /// Messages of all topics.
    pub message_count: u64,
    /// Log time of the earliest message (ns), `None` for an empty bag.
    pub start_time_ns: Option<u64>,
    /// Latest minus earliest log time (ns); 0 for one or no message.
    pub duration_ns: u64,
    /// Every declared topic, sorted by name.
    pub topics: Vec<TopicInfo>,
}

/// Records messages into a new bag directory: `<dirname>_0.mcap` (zstd-compressed chunks, ROS 2
/// profile) and, once finished, `metadata.yaml` (rosbag2 Jazzy, version 9).
///
/// Dropping it without [`BagWriter::finish`] still finishes the bag (errors go to stderr), so a
/// panic or an early return leaves a readable bag.
pub struct BagWriter {
    dir: PathBuf,
    /// The MCAP file name, relative to `dir`.
    file_name: String,
    /// `dir` joined with `file_name`.
    mcap_path: PathBuf,
    /// `None` once finished.
    mcap: Option<mcap::Writer<BufWriter<File>>>,
    topics: BTreeMap<String, Topic>,
    /// Schema id by full type name.
    schema_ids: BTreeMap<String, u16>,
    /// Earliest and latest log time written (ns).
    time_bounds: Option<(u64, u64)>,
    /// When the last chunk was closed and flushed to the file.
    last_flush: Instant,
}

impl BagWriter {
    /// Creates the bag directory `dir` (error if it exists and is not empty) with
    /// `<dirname>_0.mcap` inside.
    pub fn create(dir: &Path) -> Result<Self, BagError> {
        let dir_name =
            dir.file_name()
                .and_then(|n| n.to_str())
                .ok_or_else(|| BagError::BadPath {
                    path: dir.to_path_buf(),
                    reason: "the bag directory needs a UTF-8 final name".into(),
                })?;
        let file_name = format!("{dir_name}_0.mcap");
        if dir.exists() {
            let mut entries = std::fs::read_dir(dir).map_err(|e| BagError::io(dir, e))?;
            if entries.next().is_some() {
                return Err(BagError::DirNotEmpty {
                    path: dir.to_path_buf(),
                });
            }
        }
        std::fs::create_dir_all(dir).map_err(|e| BagError::io(dir, e))?;
        let mcap_path = dir.join(&file_name);
        let mcap = create_mcap(&mcap_path)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file_name,
            mcap_path,
            mcap: Some(mcap),
            topics: BTreeMap::new(),
            schema_ids: BTreeMap::new(),
            time_bounds: None,
            last_flush: Instant::now(),
        })
    }

    /// The bag directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The MCAP file inside the bag directory.
    pub fn mcap_path(&self) -> &Path {
        &self.mcap_path
    }

    /// Declares a topic of type `ty` offered with `durability` (optional: [`BagWriter::write`]
    /// declares unseen topics as [`Durability::Volatile`]). Declaring it again the same way does
    /// nothing; with another type or durability is an error.
    pub fn add_topic(
        &mut self,
        topic: &str,
        ty: &'static MessageType,
        durability: Durability,
    ) -> Result<(), BagError> {
        self.declare(topic, ty, Some(durability)).map(|_| ())
    }

    /// Records one message; `time_ns` is its MCAP log time and publish time (ns).
    pub fn write<M: RosMessage>(
        &mut self,
        topic: &str,
        time_ns: u64,
        msg: &M,
    ) -> Result<(), BagError> {
        let channel_id = self.declare(topic, M::TYPE, None)?;
        self.write_to_channel(topic, channel_id, time_ns, &to_cdr(msg))
    }

    /// Records already-encoded CDR bytes (with the 4-byte encapsulation header) of type `ty`.
    pub fn write_cdr(
        &mut self,
        topic: &str,
        ty: &'static MessageType,
        time_ns: u64,
        cdr: &[u8],
    ) -> Result<(), BagError> {
        let is_cdr =
            cdr.len() >= CDR_HEADER_LEN && CDR_ENCAPSULATIONS.iter().any(|e| cdr[..2] == e[..]);
        if !is_cdr {
            let reason = match cdr.get(..2) {
                Some(id) => format!("encapsulation {:02x}{:02x}", id[0], id[1]),
                None => format!("{} bytes, shorter than the header", cdr.len()),
            };
            return Err(BagError::NotCdr {
                topic: topic.into(),
                reason,
            });
        }
        let channel_id = self.declare(topic, ty, None)?;
        self.write_to_channel(topic, channel_id, time_ns, cdr)
    }

    /// Finishes the MCAP (summary, footer), then writes `metadata.yaml`. Returns where the bag
    /// is and its counts.
    pub fn finish(mut self) -> Result<BagInfo, BagError> {
        self.finish_in_place()
    }

    /// The channel of `topic`, declaring it (as `durability`, or volatile when `None`) if new.
    fn declare(
        &mut self,
        topic: &str,
        ty: &'static MessageType,
        durability: Option<Durability>,
    ) -> Result<u16, BagError> {
        if let Some(existing) = self.topics.get(topic) {
            // Same static first: no allocation on the usual path of every write.
            if !std::ptr::eq(existing.ty, ty) && existing.ty.type_name() != ty.type_name() {
                return Err(BagError::TopicTypeConflict {
                    topic: topic.into(),
                    declared: existing.ty.type_name(),
                    requested: ty.type_name(),
                });
            }
            if let Some(requested) = durability {
                if requested != existing.durability {
                    return Err(BagError::TopicDurabilityConflict {
                        topic: topic.into(),
                        declared: existing.durability,
                        requested,
                    });
                }
            }
            return Ok(existing.channel_id);
        }
        if topic.is_empty() {
            return Err(BagError::EmptyTopicName {
                topic: topic.into(),
            });
        }
        let durability = durability.unwrap_or(Durability::Volatile);
        let mcap_path = &self.mcap_path;
        let mcap = self.mcap.as_mut().expect("writer is open until finished");
        let type_name = ty.type_name();
        let schema_id = match self.schema_ids.get(&type_name) {
            Some(&id) => id,
            None => {
                let id = mcap
                    .add_schema(&type_name, SCHEMA_ENCODING, ty.schema_text().as_bytes())
                    .map_err(|e| BagError::mcap(mcap_path, e))?;
                self.schema_ids.insert(type_name, id);
                id
            }
        };
        let channel_metadata = BTreeMap::from([
            (
                QOS_METADATA_KEY.to_string(),
                durability.offered_qos_profiles_yaml(),
            ),
            (
                TYPE_HASH_METADATA_KEY.to_string(),
                type_description_hash(ty).unwrap_or_default(),
            ),
        ]);
        let channel_id = mcap
            .add_channel(schema_id, topic, SERIALIZATION_FORMAT, &channel_metadata)
            .map_err(|e| BagError::mcap(mcap_path, e))?;
        self.topics.insert(
            topic.to_string(),
            Topic {
                ty,
                durability,
                channel_id,
                message_count: 0,
            },
        );
        Ok(channel_id)
    }

    fn write_to_channel(
        &mut self,
        topic: &str,
        channel_id: u16,
        time_ns: u64,
        data: &[u8],
    ) -> Result<(), BagError> {
        let entry = self.topics.get_mut(topic).expect("declared above");
        let header = mcap::records::MessageHeader {
            channel_id,
            // MCAP sequence numbers are 32-bit; they only order messages of one channel.
            sequence: entry.message_count as u32,
            log_time: time_ns,
            publish_time: time_ns,
        };
        let mcap = self.mcap.as_mut().expect("writer is open until finished");
        mcap.write_to_known_channel(&header, data)
            .map_err(|e| BagError::mcap(&self.mcap_path, e))?;
        if self.last_flush.elapsed() >= CHUNK_FLUSH_INTERVAL {
            mcap.flush()
                .map_err(|e| BagError::mcap(&self.mcap_path, e))?;
            self.last_flush = Instant::now();
        }
        entry.message_count += 1;
        self.time_bounds = Some(match self.time_bounds {
            None => (time_ns, time_ns),
            Some((first, last)) => (first.min(time_ns), last.max(time_ns)),
        });
        Ok(())
    }

    /// The bag metadata of what has been written so far.
    fn metadata(&self) -> BagMetadata {
        let topics = self
            .topics
            .iter()
            .map(|(name, t)| TopicRecord {
                name: name.clone(),
                type_name: t.ty.type_name(),
                offered_qos_profiles: t.durability.offered_qos_profiles(),
                type_description_hash: type_description_hash(t.ty).unwrap_or_default(),
                message_count: t.message_count,
            })
            .collect();
        bag_metadata(&self.file_name, topics, self.time_bounds)
    }

    /// Finishes the MCAP and writes `metadata.yaml`; does nothing more once done.
    fn finish_in_place(&mut self) -> Result<BagInfo, BagError> {
        let mcap_path = self.mcap_path.clone();
        let metadata = self.metadata();
        if let Some(mcap) = self.mcap.take() {
            finish_mcap(mcap, &mcap_path, &metadata)?;
            write_metadata_yaml(&self.dir, metadata)?;
        }
        Ok(self.info())
    }

    fn info(&self) -> BagInfo {
        BagInfo {
            dir: self.dir.clone(),
            mcap_path: self.mcap_path.clone(),
            message_count: self.topics.values().map(|t| t.message_count).sum(),
            start_time_ns: self.time_bounds.map(|(first, _)| first),
            duration_ns: self.time_bounds.map_or(0, |(first, last)| last - first),
            topics: self
                .topics
                .iter()
                .map(|(name, t)| TopicInfo {
                    name: name.clone(),
                    type_name: t.ty.type_name(),
                    message_count: t.message_count,
                })
                .collect(),
        }
    }
}

/// A new MCAP writer on `path`: zstd-compressed chunks, the ROS 2 profile.
pub(super) fn create_mcap(path: &Path) -> Result<mcap::Writer<BufWriter<File>>, BagError> {
    let file = File::create(path).map_err(|e| BagError::io(path, e))?;
    mcap::WriteOptions::new()
        .profile(MCAP_PROFILE)
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(COMPRESSION_THREADS)
        .create(BufWriter::new(file))
        .map_err(|e| BagError::mcap(path, e))
}

/// Writes rosbag2's copy of the metadata into the MCAP at `path`, its summary and footer, and
/// flushes it to the file.
pub(super) fn finish_mcap(
    mut mcap: mcap::Writer<BufWriter<File>>,
    path: &Path,
    metadata: &BagMetadata,
) -> Result<(), BagError> {
    let serialized = serde_yaml_ng::to_string(metadata).expect("bag metadata always serialises");
    let record = mcap::records::Metadata {
        name: ROSBAG2_METADATA_RECORD.into(),
        metadata: BTreeMap::from([(SERIALIZED_METADATA_KEY.into(), serialized)]),
    };
    mcap.write_metadata(&record)
        .map_err(|e| BagError::mcap(path, e))?;
    mcap.finish().map_err(|e| BagError::mcap(path, e))?;
    mcap.into_inner()
        .into_inner()
        .map_err(|e| BagError::io(path, e.into_error()))?;
    Ok(())
}

/// Writes the bag directory's `metadata.yaml`.
pub(super) fn write_metadata_yaml(dir: &Path, metadata: BagMetadata) -> Result<(), BagError> {
    let metadata_path = dir.join(METADATA_FILE_NAME);
    let yaml = serde_yaml_ng::to_string(&MetadataFile {
        rosbag2_bagfile_information: metadata,
    })
    .expect("bag metadata always serialises");
    std::fs::write(&metadata_path, yaml).map_err(|e| BagError::io(&metadata_path, e))
}

impl Drop for BagWriter {
    /// Finishes the bag if [`BagWriter::finish`] was not called; errors go to stderr.
    fn drop(&mut self) {
        if self.mcap.is_some() {
            if let Err(e) = self.finish_in_place() {
                eprintln!("bag {}: could not finish: {e}", self.dir.display());
            }
        }
    }
}
