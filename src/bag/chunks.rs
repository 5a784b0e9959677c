//! Reading MCAP files that may be damaged. The `mcap` crate's message streams allocate a
//! chunk's declared uncompressed size before decompressing it, and a record's declared length
//! inside it before reading it, with no limit, so one corrupted size field (72 PB, found by
//! `tests/fuzz.rs`) aborted the process. A scan of the top-level records stops the read before
//! a chunk whose size cannot be believed, and chunks are checked against their CRC whole before
//! their records are read ([`read_options`]).

use mcap::read::Options;

/// How this crate streams MCAP files: chunks checked whole against their CRC before any
/// record inside is read.
pub(super) fn read_options() -> enumset::EnumSet<Options> {
    Options::ValidateChunkCrcs.into()
}

/// [`read_options`] for a file without its end (a killed recording).
pub(super) fn unfinished_read_options() -> enumset::EnumSet<Options> {
    Options::ValidateChunkCrcs | Options::IgnoreEndMagic
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
