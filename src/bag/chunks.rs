//! Reading MCAP files that may be damaged. The `mcap` crate's message streams allocate a
//! chunk's declared uncompressed size before decompressing it, and a record's declared length
//! inside it before reading it, with no limit, so one corrupted size field (72 PB, found by
//! `tests/fuzz.rs`) aborted the process. [`messages`] drives the crate's sans-io reader with
//! every length checked against [`MAX_CHUNK_BYTES`] and fed no more bytes than the file holds,
//! and checks each chunk whole against its CRC before reading a record inside it.

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

/// Largest record or chunk, compressed or not, read (bytes). Writers close chunks at about 1 MiB
/// (this crate; rosbag2 at 768 KiB); a size beyond a gigabyte is a corrupted field.
const MAX_CHUNK_BYTES: u64 = 1 << 30;
