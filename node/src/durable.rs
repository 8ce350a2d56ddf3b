//! Atomic, durable file writes: every checkpoint and snapshot a role writes goes through here, so a
//! crash or a full disk leaves either the previous file or the new one under the final name, never a
//! torn one. The temporary file is `tempfile`'s, beside the target (a rename is atomic only within
//! one file system) and removed if the write fails.

use std::fs::File;
use std::io::{self, Write};
use std::path::Path;

pub use tempfile::NamedTempFile;

/// A temporary file in `path`'s directory, to fill and then [`publish`] as `path`. It is created
/// with the permissions `File::create` gives (0666 less the umask), not `tempfile`'s private 0600:
/// the published file is a checkpoint, a record or a picture that others may read.
pub fn temporary_beside(path: &Path) -> io::Result<NamedTempFile> {
    let dir = parent(path);
    std::fs::create_dir_all(dir)?;
    let mut builder = tempfile::Builder::new();
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir)
}

/// Writes `bytes` as `path`, atomically and durably.
pub fn write(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut tmp = temporary_beside(path)?;
    tmp.write_all(bytes)?;
    publish(tmp, path)
}

/// Makes `tmp`'s contents durable (fsync), renames it over `path`, then syncs the directory: the
/// rename itself is durable only once the directory entry is (POSIX).
pub fn publish(tmp: NamedTempFile, path: &Path) -> io::Result<()> {
    tmp.as_file().sync_all()?;
    tmp.persist(path)?;
    sync_dir(parent(path))
}

fn parent(path: &Path) -> &Path {
    path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."))
}

#[cfg(unix)]
fn sync_dir(dir: &Path) -> io::Result<()> {
    File::open(dir)?.sync_all()
}

#[cfg(not(unix))]
fn sync_dir(_dir: &Path) -> io::Result<()> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("node-durable-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        dir
    }

    #[test]
    fn a_write_replaces_the_file_whole_and_leaves_no_temporary() {
        let dir = dir("replace");
        let path = dir.join("sub").join("file.bin");
        write(&path, b"first").unwrap();
        write(&path, b"second, longer").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"second, longer");
        let names: Vec<_> =
            std::fs::read_dir(path.parent().unwrap()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, ["file.bin"]);
        // Readable by others, as a plain `File::create` would leave it (umask 022 here).
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let created = dir.join("created.bin");
            std::fs::write(&created, b"x").unwrap();
            let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode(&path), mode(&created));
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_failed_write_keeps_the_old_file_and_removes_its_temporary() {
        let dir = dir("failed");
        let path = dir.join("file.bin");
        write(&path, b"old").unwrap();
        {
            let mut tmp = temporary_beside(&path).unwrap();
            tmp.write_all(b"half of the new").unwrap();
            // Dropped unpublished, as when serialising fails half-way.
        }
        assert_eq!(std::fs::read(&path).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        // A target that is a directory cannot be replaced: an error, and the directory stays.
        let blocked = dir.join("blocked");
        std::fs::create_dir_all(blocked.join("inside")).unwrap();
        assert!(write(&blocked, b"x").is_err());
        assert!(blocked.join("inside").is_dir());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2, "no temporary left");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
