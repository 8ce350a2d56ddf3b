//! Parameter snapshots and training checkpoints as safetensors bytes.
//!
//! Tensor names are `{network}.{vb.pp path}`, e.g. `policy.coupling0.scale.layer0.weight`,
//! `q1.layer0.weight_action`, `v_target.layer2.bias`, so checkpoints, the parameter broadcast and the
//! executors' load agree. Networks: `policy`, `q1`, `q2` (twin Q only), `v`, `v_target`.
//!
//! The bytes are written here (an 8-byte little-endian header length, a JSON header, raw
//! little-endian data: the safetensors format) to avoid a dependency; they are read with candle's
//! safetensors loader, so any safetensors tool can open them.

use std::collections::HashMap;

use candle_core::{DType, Device, Tensor};
use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// The weights of every network at one learner step, for broadcasting to executors and checkpoints.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ParamSnapshot {
    /// The learner step (number of updates) the weights are from.
    pub version: u64,
    /// safetensors bytes of all networks; names as in the module doc.
    pub safetensors: Vec<u8>,
}

impl ParamSnapshot {
    /// The tensors, by name.
    pub fn tensors(&self) -> Result<HashMap<String, Tensor>> {
        decode(&self.safetensors)
    }
}

/// The full training state of a [`Learner`](crate::Learner): networks, target, temperature, Adam
/// moments and step counts, the learner step and its seed. Restoring it resumes bit-identically.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The learner step.
    pub step: u64,
    /// safetensors bytes: the snapshot's tensors plus `temperature.log_alpha`,
    /// `adam.{network}.{m,v}.{name}`, `adam.{network}.steps`, `learner.step`, `learner.seed`.
    pub safetensors: Vec<u8>,
}

fn dtype_name(dtype: DType) -> Result<&'static str> {
    Ok(match dtype {
        DType::F32 => "F32",
        DType::F64 => "F64",
        DType::I64 => "I64",
        other => return Err(Error::BadSnapshot(format!("unsupported dtype {other:?}"))),
    })
}

fn le_bytes(t: &Tensor) -> Result<Vec<u8>> {
    let flat = t.flatten_all()?;
    Ok(match t.dtype() {
        DType::F32 => flat.to_vec1::<f32>()?.iter().flat_map(|x| x.to_le_bytes()).collect(),
        DType::F64 => flat.to_vec1::<f64>()?.iter().flat_map(|x| x.to_le_bytes()).collect(),
        DType::I64 => flat.to_vec1::<i64>()?.iter().flat_map(|x| x.to_le_bytes()).collect(),
        other => return Err(Error::BadSnapshot(format!("unsupported dtype {other:?}"))),
    })
}

fn json_string(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

/// Serialises named tensors (sorted by name) with string metadata to safetensors bytes.
pub(crate) fn encode(tensors: &[(String, Tensor)], metadata: &[(&str, String)]) -> Result<Vec<u8>> {
    let mut sorted: Vec<&(String, Tensor)> = tensors.iter().collect();
    sorted.sort_by(|a, b| a.0.cmp(&b.0));
    let mut entries = Vec::with_capacity(sorted.len() + 1);
    if !metadata.is_empty() {
        let kv: Vec<String> =
            metadata.iter().map(|(k, v)| format!("{}:{}", json_string(k), json_string(v))).collect();
        entries.push(format!("\"__metadata__\":{{{}}}", kv.join(",")));
    }
    let mut data = Vec::new();
    for (name, t) in sorted {
        let bytes = le_bytes(t)?;
        let shape: Vec<String> = t.dims().iter().map(|d| d.to_string()).collect();
        entries.push(format!(
            "{}:{{\"dtype\":\"{}\",\"shape\":[{}],\"data_offsets\":[{},{}]}}",
            json_string(name),
            dtype_name(t.dtype())?,
            shape.join(","),
            data.len(),
            data.len() + bytes.len()
        ));
        data.extend_from_slice(&bytes);
    }
    let mut header = format!("{{{}}}", entries.join(","));
    while !header.len().is_multiple_of(8) {
        header.push(' ');
    }
    let mut out = Vec::with_capacity(8 + header.len() + data.len());
    out.extend_from_slice(&(header.len() as u64).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(&data);
    Ok(out)
}

/// Reads safetensors bytes into CPU tensors.
pub(crate) fn decode(bytes: &[u8]) -> Result<HashMap<String, Tensor>> {
    candle_core::safetensors::load_buffer(bytes, &Device::Cpu).map_err(|e| Error::BadSnapshot(e.to_string()))
}

/// A scalar i64 tensor from `tensors[key]`.
/// The learner step a snapshot's or checkpoint's tensors were saved at (`learner.step`), if they
/// say (and it is not negative).
pub fn saved_learner_step(tensors: &HashMap<String, Tensor>) -> Option<u64> {
    read_i64(tensors, "learner.step").ok().and_then(|step| u64::try_from(step).ok())
}

pub(crate) fn read_i64(tensors: &HashMap<String, Tensor>, key: &str) -> Result<i64> {
    let t = tensors.get(key).ok_or_else(|| Error::BadSnapshot(format!("missing tensor {key}")))?;
    t.to_vec1::<i64>()?.first().copied().ok_or_else(|| Error::BadSnapshot(format!("{key} is empty")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn encode_decode_round_trip_keeps_names_shapes_values() {
        let dev = Device::Cpu;
        let a = Tensor::new(&[[1f32, 2.0, 3.0], [4.0, 5.0, 6.0]], &dev).unwrap();
        let b = Tensor::new(&[0.5f64], &dev).unwrap();
        let c = Tensor::new(&[-7i64], &dev).unwrap();
        let named = vec![("q1.layer0.weight".to_string(), a.clone()), ("x\"y".into(), b), ("meta".into(), c)];
        let bytes = encode(&named, &[("version", "12".into())]).unwrap();
        let back = decode(&bytes).unwrap();
        assert_eq!(back.len(), 3);
        assert_eq!(back["q1.layer0.weight"].to_vec2::<f32>().unwrap(), a.to_vec2::<f32>().unwrap());
        assert_eq!(back["x\"y"].to_vec1::<f64>().unwrap(), vec![0.5]);
        assert_eq!(read_i64(&back, "meta").unwrap(), -7);
    }
}
