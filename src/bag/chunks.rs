//! Reading MCAP files that may be damaged. The `mcap` crate's message streams allocate a
//! chunk's declared uncompressed size before decompressing it, and a record's declared length
//! inside it before reading it, with no limit, so one corrupted size field (72 PB, found by
//! `tests/fuzz.rs`) aborted the process. [`messages`] drives the crate's sans-io reader with
//! every length checked against [`MAX_CHUNK_BYTES`] and fed no more bytes than the file holds,
//! and checks each chunk whole against its CRC before reading a record inside it; a scan of
//! the top-level records ([`believable_prefix`]) finds where a file stops being readable.

use mcap::sans_io::{LinearReaderOptions, MessageReadEvent, MessageReader};

/// Every message of the MCAP file `bytes`, in file order, linked to its channel. A finished
/// file is read to its closing magic; an `unfinished` one (a killed recording) to its data end
/// record or the first record cut off, which ends the iteration with an error.
pub(super) fn messages(bytes: &[u8], unfinished: bool) -> Messages<'_> {
    let record_length_limit = usize::try_from(MAX_CHUNK_BYTES).unwrap_or(usize::MAX);
    let options = LinearReaderOptions::default()
        .with_record_length_limit(record_length_limit)
        .with_prevalidate_chunk_crcs(true)
        .with_skip_end_magic(unfinished);
    Messages {
        reader: MessageReader::new_with_options(options),
        unread: bytes,
        done: false,
    }
}

/// The iterator of [`messages`]; it ends after its first error.
pub(super) struct Messages<'a> {
    reader: MessageReader,
    /// The file's bytes not yet given to the reader.
    unread: &'a [u8],
    done: bool,
}

impl Iterator for Messages<'_> {
    type Item = mcap::McapResult<mcap::Message<'static>>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        while let Some(event) = self.reader.next_event() {
            match event {
                // The reader asks for a record's declared length, which may be corrupted:
                // it gets what the file has (none at its end, which it takes as the end).
                Ok(MessageReadEvent::ReadRequest(wanted)) => {
                    let given = wanted.min(self.unread.len());
                    let (now, later) = self.unread.split_at(given);
                    self.reader.insert(given).copy_from_slice(now);
                    self.reader.notify_read(given);
                    self.unread = later;
                }
                Ok(MessageReadEvent::Message(message)) => return Some(Ok(message)),
                Err(error) => {
                    self.done = true;
                    return Some(Err(error));
                }
            }
        }
        self.done = true;
        None
    }
}

/// Opcodes of the records the scan looks at (MCAP specification).
const OP_CHUNK: u8 = 0x06;
const OP_DATA_END: u8 = 0x0F;
/// A record: opcode (1 byte) and body length (u64, little endian), then the body.
const RECORD_HEADER_BYTES: usize = 9;
/// Where a chunk's uncompressed size (u64) sits in its body: after its message start and end
/// times.
const CHUNK_UNCOMPRESSED_SIZE_AT: usize = 16;
/// Largest uncompressed chunk read (bytes). Writers close chunks at about 1 MiB (this crate;
/// rosbag2 at 768 KiB); a size beyond a gigabyte is a corrupted field.
const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// The length of the file's prefix up to the first chunk whose declared size cannot be
/// believed, and what is wrong with it; the whole length and `None` if there is none.
pub(super) fn believable_prefix(bytes: &[u8]) -> (usize, Option<String>) {
    let u64_at = |at: usize| -> Option<u64> {
        let field = bytes.get(at..at.checked_add(8)?)?;
        Some(u64::from_le_bytes(field.try_into().ok()?))
    };
    let mut at = mcap::MAGIC.len();
    while at + RECORD_HEADER_BYTES <= bytes.len() {
        let op = bytes[at];
        let Some(body_len) = u64_at(at + 1) else {
            break;
        };
        let body = at + RECORD_HEADER_BYTES;
        let end = usize::try_from(body_len)
            .ok()
            .and_then(|len| body.checked_add(len))
            .unwrap_or(usize::MAX);
        if op == OP_DATA_END {
            break;
        }
        // A chunk cut off by the end of the file is checked too: the crate starts
        // decompressing it (allocating its declared size) before it finds it cut.
        if op == OP_CHUNK {
            if let Some(size) = u64_at(body + CHUNK_UNCOMPRESSED_SIZE_AT) {
                if size > MAX_CHUNK_BYTES {
                    return (
                        at,
                        Some(format!(
                            "the chunk at byte {at} declares {size} bytes uncompressed (over \
                             {MAX_CHUNK_BYTES}): the file is corrupted from there on"
                        )),
                    );
                }
            }
        }
        if end > bytes.len() {
            break;
        }
        at = end;
    }
    (bytes.len(), None)
}
