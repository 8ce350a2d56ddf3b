//! TensorBoard event files, so `tensorboard --logdir runs` shows a run's scalars live.
//!
//! The format is small and stable: a file `events.out.tfevents.<unix s>.<host>.<pid>.sac-lsp` is a
//! sequence of TFRecords, each `u64 length (LE) · u32 masked-crc32c(length) · data · u32
//! masked-crc32c(data)`, where a masked CRC is `((c >> 15) | (c << 17)) + 0xa282ead8`. Each record's
//! data is a `tensorflow.Event` protobuf; the first carries `file_version = "brain.Event:2"`, the rest
//! one `Summary` of scalar values:
//!
//! ```text
//! Event   { double wall_time = 1; int64 step = 2; string file_version = 3; Summary summary = 5; }
//! Summary { repeated Value value = 1; }
//! Value   { string tag = 1; float simple_value = 2; }
//! ```
//!
//! Those three messages are all a scalar writer needs, so they are encoded here by hand rather than
//! through a protobuf code generator; the CRC is the `crc32c` crate's.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

/// One scalar point: a named value at a step.
#[derive(Debug, Clone, PartialEq)]
pub struct Scalar {
    /// The chart's name; `/` groups charts into sections.
    pub tag: String,
    /// The value (TensorBoard stores `f32`).
    pub value: f64,
}

impl Scalar {
    /// `tag = value`.
    pub fn new(tag: impl Into<String>, value: f64) -> Scalar {
        Scalar { tag: tag.into(), value }
    }
}

/// An open event file. Events are buffered; [`EventWriter::flush`] makes them visible.
#[derive(Debug)]
pub struct EventWriter {
    path: PathBuf,
    out: BufWriter<File>,
}

impl EventWriter {
    /// Creates a new event file in `dir` (and `dir` itself). TensorBoard reads every event file of a
    /// folder in name order, so a restarted writer adds a file rather than rewriting one.
    pub fn create(dir: &Path, wall_time_s: f64) -> Result<EventWriter> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let host = hostname();
        let name =
            format!("events.out.tfevents.{}.{host}.{}.sac-lsp", wall_time_s as u64, std::process::id());
        let path = dir.join(name);
        let file = File::create(&path).with_context(|| format!("creating {}", path.display()))?;
        let mut writer = EventWriter { path, out: BufWriter::new(file) };
        writer.write_record(&encode_event(wall_time_s, 0, EventBody::FileVersion))?;
        writer.flush()?;
        Ok(writer)
    }

    /// Appends one event holding `scalars` at `step`. Non-finite values are written as they are:
    /// TensorBoard shows them, and a gap would hide that a loss diverged.
    pub fn write(&mut self, wall_time_s: f64, step: u64, scalars: &[Scalar]) -> Result<()> {
        if scalars.is_empty() {
            return Ok(());
        }
        self.write_record(&encode_event(wall_time_s, step, EventBody::Scalars(scalars)))
    }

    /// Writes out the buffered events.
    pub fn flush(&mut self) -> Result<()> {
        self.out.flush().with_context(|| format!("writing {}", self.path.display()))
    }

    /// The file written to.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn write_record(&mut self, data: &[u8]) -> Result<()> {
        let length = (data.len() as u64).to_le_bytes();
        let frame = [&length[..], &masked_crc(&length).to_le_bytes(), data, &masked_crc(data).to_le_bytes()];
        for part in frame {
            self.out.write_all(part).with_context(|| format!("writing {}", self.path.display()))?;
        }
        Ok(())
    }
}

/// The machine's name for the file name (TensorBoard's convention); `localhost` if unknown.
fn hostname() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().chars().filter(|c| c.is_ascii_alphanumeric() || *c == '-').collect::<String>())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "localhost".to_string())
}

fn masked_crc(bytes: &[u8]) -> u32 {
    let crc = crc32c::crc32c(bytes);
    crc.rotate_right(15).wrapping_add(0xa282_ead8)
}

enum EventBody<'a> {
    FileVersion,
    Scalars(&'a [Scalar]),
}

/// Protobuf wire types.
const VARINT: u8 = 0;
const FIXED64: u8 = 1;
const LEN: u8 = 2;
const FIXED32: u8 = 5;

fn encode_event(wall_time_s: f64, step: u64, body: EventBody<'_>) -> Vec<u8> {
    let mut event = Vec::new();
    key(&mut event, 1, FIXED64);
    event.extend_from_slice(&wall_time_s.to_le_bytes());
    key(&mut event, 2, VARINT);
    varint(&mut event, step);
    match body {
        EventBody::FileVersion => bytes_field(&mut event, 3, b"brain.Event:2"),
        EventBody::Scalars(scalars) => {
            let mut summary = Vec::new();
            for scalar in scalars {
                let mut value = Vec::new();
                bytes_field(&mut value, 1, scalar.tag.as_bytes());
                key(&mut value, 2, FIXED32);
                value.extend_from_slice(&(scalar.value as f32).to_le_bytes());
                bytes_field(&mut summary, 1, &value);
            }
            bytes_field(&mut event, 5, &summary);
        }
    }
    event
}

fn key(out: &mut Vec<u8>, field: u64, wire_type: u8) {
    varint(out, (field << 3) | u64::from(wire_type));
}

fn varint(out: &mut Vec<u8>, mut v: u64) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn bytes_field(out: &mut Vec<u8>, field: u64, bytes: &[u8]) {
    key(out, field, LEN);
    varint(out, bytes.len() as u64);
    out.extend_from_slice(bytes);
}

/// A reader of what [`EventWriter`] writes, checking every CRC: the tests' way to read events back.
#[cfg(test)]
pub mod read {
    use super::*;

    /// One event as read back.
    #[derive(Debug, Clone, PartialEq)]
    pub struct Event {
        /// Seconds since the Unix epoch.
        pub wall_time_s: f64,
        /// The step.
        pub step: u64,
        /// `file_version`, if set.
        pub file_version: Option<String>,
        /// The scalars of its summary, values as stored (f32).
        pub scalars: Vec<(String, f32)>,
    }

    /// Every event of `path`; panics on a bad CRC or a field this writer never writes.
    pub fn events(path: &Path) -> Vec<Event> {
        let bytes = std::fs::read(path).unwrap();
        let mut at = 0;
        let mut events = Vec::new();
        while at < bytes.len() {
            let length_bytes = &bytes[at..at + 8];
            let length = u64::from_le_bytes(length_bytes.try_into().unwrap()) as usize;
            assert_eq!(u32_at(&bytes, at + 8), masked_crc(length_bytes), "length CRC");
            let data = &bytes[at + 12..at + 12 + length];
            assert_eq!(u32_at(&bytes, at + 12 + length), masked_crc(data), "data CRC");
            events.push(event(data));
            at += 12 + length + 4;
        }
        events
    }

    fn u32_at(bytes: &[u8], at: usize) -> u32 {
        u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap())
    }

    fn event(data: &[u8]) -> Event {
        let mut event = Event { wall_time_s: 0.0, step: 0, file_version: None, scalars: Vec::new() };
        for (field, value) in fields(data) {
            match (field, value) {
                (1, Field::Fixed64(v)) => event.wall_time_s = f64::from_le_bytes(v),
                (2, Field::Varint(v)) => event.step = v,
                (3, Field::Bytes(b)) => event.file_version = Some(String::from_utf8(b.to_vec()).unwrap()),
                (5, Field::Bytes(summary)) => {
                    for (field, value) in fields(summary) {
                        let (1, Field::Bytes(value)) = (field, value) else {
                            panic!("summary field {field}")
                        };
                        let (mut tag, mut simple) = (String::new(), f32::NAN);
                        for (field, v) in fields(value) {
                            match (field, v) {
                                (1, Field::Bytes(b)) => tag = String::from_utf8(b.to_vec()).unwrap(),
                                (2, Field::Fixed32(b)) => simple = f32::from_le_bytes(b),
                                _ => panic!("value field {field}"),
                            }
                        }
                        event.scalars.push((tag, simple));
                    }
                }
                _ => panic!("event field {field}"),
            }
        }
        event
    }

    enum Field<'a> {
        Varint(u64),
        Fixed64([u8; 8]),
        Fixed32([u8; 4]),
        Bytes(&'a [u8]),
    }

    fn fields(mut data: &[u8]) -> Vec<(u64, Field<'_>)> {
        let mut out = Vec::new();
        while !data.is_empty() {
            let key = read_varint(&mut data);
            let field = match (key & 7) as u8 {
                VARINT => Field::Varint(read_varint(&mut data)),
                FIXED64 => {
                    let (v, rest) = data.split_at(8);
                    data = rest;
                    Field::Fixed64(v.try_into().unwrap())
                }
                FIXED32 => {
                    let (v, rest) = data.split_at(4);
                    data = rest;
                    Field::Fixed32(v.try_into().unwrap())
                }
                LEN => {
                    let n = read_varint(&mut data) as usize;
                    let (v, rest) = data.split_at(n);
                    data = rest;
                    Field::Bytes(v)
                }
                other => panic!("wire type {other}"),
            };
            out.push((key >> 3, field));
        }
        out
    }

    fn read_varint(data: &mut &[u8]) -> u64 {
        let mut v = 0u64;
        for shift in (0..64).step_by(7) {
            let b = data[0];
            *data = &data[1..];
            v |= u64::from(b & 0x7f) << shift;
            if b < 0x80 {
                return v;
            }
        }
        panic!("varint too long")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masked_crc_matches_tensorflow() {
        // TensorFlow's crc32c unit test vector: crc32c("123456789") = 0xe3069283; masked by hand.
        assert_eq!(crc32c::crc32c(b"123456789"), 0xe306_9283);
        assert_eq!(masked_crc(b"123456789"), 0xe306_9283u32.rotate_right(15).wrapping_add(0xa282_ead8));
    }

    #[test]
    fn varints_encode_as_protobuf() {
        let enc = |v| {
            let mut out = Vec::new();
            varint(&mut out, v);
            out
        };
        assert_eq!(enc(1), [1]);
        assert_eq!(enc(150), [0x96, 0x01]);
        assert_eq!(enc(u64::MAX).len(), 10);
    }

    #[test]
    fn written_events_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let mut writer = EventWriter::create(dir.path(), 1_700_000_000.5).unwrap();
        writer
            .write(1_700_000_001.0, 4000, &[Scalar::new("eval/return", 812.25), Scalar::new("loss/q", 0.5)])
            .unwrap();
        writer.write(1_700_000_002.0, 8000, &[]).unwrap();
        writer.write(1_700_000_003.0, 300_000, &[Scalar::new("loss/q", f64::NAN)]).unwrap();
        writer.flush().unwrap();
        let name = writer.path().file_name().unwrap().to_str().unwrap().to_string();
        assert!(name.starts_with("events.out.tfevents.1700000000."), "{name}");

        let events = read::events(writer.path());
        assert_eq!(events.len(), 3, "the empty write adds nothing");
        assert_eq!(events[0].file_version.as_deref(), Some("brain.Event:2"));
        assert_eq!(events[0].wall_time_s, 1_700_000_000.5);
        assert_eq!(events[1].step, 4000);
        assert_eq!(events[1].scalars, [("eval/return".to_string(), 812.25), ("loss/q".to_string(), 0.5)]);
        assert_eq!(events[2].step, 300_000);
        assert!(events[2].scalars[0].1.is_nan());
    }
}
