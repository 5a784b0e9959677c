//! `sandstep bag reindex`: finishes a bag whose writer was killed (SIGKILL, the out-of-memory
//! killer, a power loss), as `ros2 bag reindex` does for rosbag2. The messages of the MCAP
//! file's complete chunks (the writer closes one at least every second) are written again into
//! a finished MCAP file (summary, footer, rosbag2's metadata record) under the same name, and
//! `metadata.yaml` is written beside it; the unfinished file is kept as `<name>.unfinished`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use super::chunks::messages;
use super::metadata::{bag_metadata, Durability, QosProfile, TopicRecord};
use super::reader::{full_type_name, single_mcap};
use super::writer::{
    create_mcap, finish_mcap, write_metadata_yaml, QOS_METADATA_KEY, TYPE_HASH_METADATA_KEY,
};
use super::{BagError, METADATA_FILE_NAME};

/// Suffix of the unfinished MCAP file kept beside the finished one.
const UNFINISHED_SUFFIX: &str = "unfinished";
/// Suffix of the finished file while it is being written.
const PARTIAL_SUFFIX: &str = "reindexing";

/// What [`reindex`] did.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Reindexed {
    /// The finished MCAP file.
    pub mcap_path: PathBuf,
    /// The unfinished file, kept.
    pub unfinished_path: PathBuf,
    /// Messages recovered.
    pub message_count: u64,
    /// Log time of the last message recovered (ns); `None` without any.
    pub last_time_ns: Option<u64>,
}

/// One channel of the unfinished file, as re-declared in the finished one.
struct Channel {
    new_id: u16,
    record: TopicRecord,
}

/// Finishes the bag directory `dir` (the one `.mcap` inside it, without `metadata.yaml`).
pub fn reindex(dir: &Path) -> Result<Reindexed, BagError> {
    let mcap_path = single_mcap(dir)?;
    let bytes = std::fs::read(&mcap_path).map_err(|e| BagError::io(&mcap_path, e))?;
    if bytes.ends_with(mcap::MAGIC) && dir.join(METADATA_FILE_NAME).exists() {
        return Err(BagError::Metadata {
            path: dir.to_path_buf(),
            message: "the bag is finished (its MCAP file is whole and metadata.yaml exists): \
                      nothing to reindex"
                .into(),
        });
    }
    let partial_path = with_suffix(&mcap_path, PARTIAL_SUFFIX);
    let mut out = create_mcap(&partial_path)?;
    let mcap_err = |e| BagError::mcap(&partial_path, e);
    let mut channels: BTreeMap<u16, Channel> = BTreeMap::new();
    let mut schemas: BTreeMap<u16, u16> = BTreeMap::new();
    let (mut message_count, mut time_bounds) = (0u64, None::<(u64, u64)>);
    // Messages in file order; a chunk cut off by the kill (or damaged) ends the loop with an
    // error and nothing of it is written.
    for message in messages(&bytes, true).map_while(Result::ok) {
        let source = &message.channel;
        if let std::collections::btree_map::Entry::Vacant(entry) = channels.entry(source.id) {
            let schema_id = match &source.schema {
                Some(schema) => match schemas.get(&schema.id) {
                    Some(&id) => id,
                    None => {
                        let id = out
                            .add_schema(&schema.name, &schema.encoding, &schema.data)
                            .map_err(mcap_err)?;
                        schemas.insert(schema.id, id);
                        id
                    }
                },
                None => 0,
            };
            let new_id = out
                .add_channel(
                    schema_id,
                    &source.topic,
                    &source.message_encoding,
                    &source.metadata,
                )
                .map_err(mcap_err)?;
            let record = topic_record(source);
            entry.insert(Channel { new_id, record });
        }
        let channel = channels.get_mut(&source.id).expect("added above");
        let new_header = mcap::records::MessageHeader {
            channel_id: channel.new_id,
            sequence: message.sequence,
            log_time: message.log_time,
            publish_time: message.publish_time,
        };
        out.write_to_known_channel(&new_header, &message.data)
            .map_err(mcap_err)?;
        channel.record.message_count += 1;
        message_count += 1;
        let t = message.log_time;
        time_bounds = Some(time_bounds.map_or((t, t), |(a, b)| (a.min(t), b.max(t))));
    }
    let file_name = file_name_of(&mcap_path);
    let metadata = bag_metadata(
        &file_name,
        channels.into_values().map(|c| c.record).collect(),
        time_bounds,
    );
    finish_mcap(out, &partial_path, &metadata)?;
    let unfinished_path = with_suffix(&mcap_path, UNFINISHED_SUFFIX);
    std::fs::rename(&mcap_path, &unfinished_path).map_err(|e| BagError::io(&mcap_path, e))?;
    std::fs::rename(&partial_path, &mcap_path).map_err(|e| BagError::io(&partial_path, e))?;
    write_metadata_yaml(dir, metadata)?;
    Ok(Reindexed {
        mcap_path,
        unfinished_path,
        message_count,
        last_time_ns: time_bounds.map(|(_, last)| last),
    })
}

/// The topic of an MCAP channel as `metadata.yaml` lists it (no message counted yet): its QoS
/// and type hash from the channel's metadata, as [`super::BagWriter`] wrote them.
fn topic_record(channel: &mcap::Channel) -> TopicRecord {
    TopicRecord {
        name: channel.topic.clone(),
        type_name: channel
            .schema
            .as_ref()
            .map(|s| full_type_name(&s.name))
            .unwrap_or_default(),
        offered_qos_profiles: channel
            .metadata
            .get(QOS_METADATA_KEY)
            .and_then(|yaml| serde_yaml_ng::from_str::<Vec<QosProfile>>(yaml).ok())
            .unwrap_or_else(|| Durability::Volatile.offered_qos_profiles()),
        type_description_hash: channel
            .metadata
            .get(TYPE_HASH_METADATA_KEY)
            .cloned()
            .unwrap_or_default(),
        message_count: 0,
    }
}

/// `path` with `.suffix` added after its extension.
fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".");
    name.push(suffix);
    PathBuf::from(name)
}

fn file_name_of(path: &Path) -> String {
    path.file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default()
}
