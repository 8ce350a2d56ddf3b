//! The JSONL record file: appended to, never truncated, so restarting the monitor keeps what an
//! earlier session recorded.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// An open record file. Lines are buffered; [`Journal::flush`] (every tick) makes them visible.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    out: BufWriter<File>,
}

impl Journal {
    /// Opens `path` for appending, creating it and its parent folders.
    pub fn open(path: &Path) -> Result<Journal> {
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("opening {}", path.display()))?;
        Ok(Journal { path: path.to_path_buf(), out: BufWriter::new(file) })
    }

    /// Appends one line (`line` holds no newline).
    pub fn append(&mut self, line: &str) -> Result<()> {
        writeln!(self.out, "{line}").with_context(|| format!("writing {}", self.path.display()))
    }

    /// Writes out the buffered lines.
    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().with_context(|| format!("writing {}", self.path.display()))
    }

    /// Where the record goes.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn appends_across_sessions_and_creates_folders() {
        let dir = std::env::temp_dir().join(format!("sac-lsp-journal-{}", std::process::id()));
        let path = dir.join("a/b/monitor.jsonl");
        let _ = std::fs::remove_dir_all(&dir);
        for line in ["{\"n\":1}", "{\"n\":2}"] {
            let mut journal = Journal::open(&path).unwrap();
            journal.append(line).unwrap();
            journal.flush().unwrap();
        }
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"n\":1}\n{\"n\":2}\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
