//! Files written whole or not at all: the bytes go to a temporary file beside the target,
//! flushed to disk, which is then renamed over it. Processes that write the same file at once
//! (the shards of one study in a shared folder, `docs/cluster.md`) never leave, or read, half
//! a file; a file that already holds the bytes is left alone, so one that another process
//! has open is not replaced under it.

use std::io::Write;
use std::path::Path;

/// What `open(2)` is asked for by a plain `std::fs::write`; the umask is taken off it.
#[cfg(unix)]
const PLAIN_FILE_MODE: u32 = 0o666;

/// Writes `bytes` to `path` atomically (a rename on the same file system), with the
/// permissions a plain write would give it (read-write for all, less the umask); nothing is
/// written if `path` already holds `bytes`.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if std::fs::read(path).is_ok_and(|held| held == bytes) {
        return Ok(());
    }
    let dir = match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir,
        _ => Path::new("."),
    };
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(
        PLAIN_FILE_MODE,
    ));
    let mut file = builder.tempfile_in(dir)?;
    file.write_all(bytes)?;
    // On disk before the rename makes it visible: a crash never leaves an empty file.
    file.as_file().sync_all()?;
    file.persist(path).map_err(|e| e.error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_file_and_leaves_no_temporary_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomically(&path, b"first").unwrap();
        write_atomically(&path, b"second").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        // Readable by others as a plain write's file is (the umask permitting), not 0600.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let plain = dir.path().join("b.txt");
            std::fs::write(&plain, b"x").unwrap();
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&plain));
        }
    }

    #[cfg(unix)]
    #[test]
    fn a_file_holding_the_bytes_is_left_alone() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.txt");
        write_atomically(&path, b"same").unwrap();
        let inode = |p: &Path| {
            use std::os::unix::fs::MetadataExt;
            std::fs::metadata(p).unwrap().ino()
        };
        let before = inode(&path);
        write_atomically(&path, b"same").unwrap();
        assert_eq!(inode(&path), before, "not replaced");
        write_atomically(&path, b"other").unwrap();
        assert_ne!(inode(&path), before, "replaced");
    }

    #[test]
    fn a_missing_folder_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert!(write_atomically(&dir.path().join("no/such/a.txt"), b"x").is_err());
    }
}
