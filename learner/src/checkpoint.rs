//! Checkpoints on disk: `<dir>/learner-<step>.safetensors`, written atomically (`node::durable`:
//! temporary file, fsync, rename), the newest few kept; at start the newest one is resumed from.

use std::fs;
use std::path::PathBuf;

use agent::Checkpoint;

/// How many checkpoints stay on disk.
const KEEP: usize = 3;
const PREFIX: &str = "learner-";
const SUFFIX: &str = ".safetensors";

/// A directory of learner checkpoints.
#[derive(Debug, Clone)]
pub struct CheckpointDir {
    dir: PathBuf,
}

impl CheckpointDir {
    /// The directory (created on first write).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        Self { dir: dir.into() }
    }

    fn path(&self, step: u64) -> PathBuf {
        self.dir.join(format!("{PREFIX}{step:012}{SUFFIX}"))
    }

    /// Steps of the checkpoints present, ascending.
    pub fn steps(&self) -> std::io::Result<Vec<u64>> {
        let entries = match fs::read_dir(&self.dir) {
            Ok(entries) => entries,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            Err(e) => return Err(e),
        };
        let mut steps: Vec<u64> = entries
            .filter_map(|e| e.ok())
            .filter_map(|e| {
                let name = e.file_name().into_string().ok()?;
                name.strip_prefix(PREFIX)?.strip_suffix(SUFFIX)?.parse().ok()
            })
            .collect();
        steps.sort_unstable();
        Ok(steps)
    }

    /// The newest checkpoint, if any.
    pub fn latest(&self) -> std::io::Result<Option<Checkpoint>> {
        let Some(&step) = self.steps()?.last() else { return Ok(None) };
        let safetensors = fs::read(self.path(step))?;
        Ok(Some(Checkpoint { step, safetensors }))
    }

    /// The checkpoint of `step`, if it is on disk.
    pub fn at(&self, step: u64) -> std::io::Result<Option<Checkpoint>> {
        match fs::read(self.path(step)) {
            Ok(safetensors) => Ok(Some(Checkpoint { step, safetensors })),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// Writes `checkpoint` atomically and removes all but the newest few. Returns its path.
    pub fn write(&self, checkpoint: &Checkpoint) -> std::io::Result<PathBuf> {
        let path = self.path(checkpoint.step);
        node::durable::write(&path, &checkpoint.safetensors)?;
        let steps = self.steps()?;
        for old in steps.iter().take(steps.len().saturating_sub(KEEP)) {
            let _ = fs::remove_file(self.path(*old));
        }
        Ok(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_atomically_keeps_the_newest_and_finds_the_latest() {
        let dir = std::env::temp_dir().join(format!("ckpt-test-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        let c = CheckpointDir::new(&dir);
        assert!(c.latest().unwrap().is_none());
        for step in [5, 1000, 20, 3000, 4000] {
            c.write(&Checkpoint { step, safetensors: vec![step as u8; 3] }).unwrap();
        }
        assert_eq!(c.steps().unwrap(), vec![1000, 3000, 4000]);
        let latest = c.latest().unwrap().unwrap();
        assert_eq!((latest.step, latest.safetensors), (4000, vec![4000u64 as u8; 3]));
        assert_eq!(c.at(3000).unwrap().map(|c| c.step), Some(3000));
        assert!(c.at(20).unwrap().is_none(), "removed");
        fs::write(dir.join("learner-junk.safetensors"), b"x").unwrap();
        assert_eq!(c.steps().unwrap().len(), 3, "foreign names are ignored");
        fs::remove_dir_all(&dir).unwrap();
    }
}
