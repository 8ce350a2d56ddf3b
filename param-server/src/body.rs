//! What the param server checks in a weights frame's body before it accepts or serves it: a
//! well-formed safetensors file (header, offsets and sizes, via the `safetensors` crate), f32
//! tensors with finite values only, and the tensor names and shapes of the run's networks. One
//! corrupt or forged frame would otherwise reach every executor that fetches it.
//!
//! The schema comes from the run file (`[agent]` with the widths of `[train] task` and `[her]`,
//! through `agent::snapshot_schema`, which builds no network); a configuration without networks
//! (tests of the store alone) falls back to the first frame accepted. Executors check each snapshot against
//! their own networks as well, all or nothing, and keep acting when one fails.

pub use agent::Schema;
use safetensors::{Dtype, SafeTensors};

/// Why a body was refused: a `weights/<reason>` count and a detail for the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadBody {
    /// Short reason, the count's key suffix.
    pub reason: &'static str,
    /// What exactly is wrong.
    pub detail: String,
}

fn bad(reason: &'static str, detail: String) -> BadBody {
    BadBody { reason, detail }
}

/// Checks `body` and returns its schema; with `expected`, its schema must be that one.
pub fn check_body(body: &[u8], expected: Option<&Schema>) -> Result<Schema, BadBody> {
    let tensors = SafeTensors::deserialize(body).map_err(|e| bad("bad_safetensors", e.to_string()))?;
    let mut schema = Schema::new();
    for (name, view) in tensors.tensors() {
        if view.dtype() != Dtype::F32 {
            return Err(bad("bad_dtype", format!("{name}: {:?}, not F32", view.dtype())));
        }
        let data = view.data();
        if let Some(v) = data
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .find(|v| !v.is_finite())
        {
            return Err(bad("non_finite", format!("{name}: value {v}")));
        }
        schema.insert(name, view.shape().to_vec());
    }
    if schema.is_empty() {
        return Err(bad("bad_safetensors", "no tensors".into()));
    }
    if let Some(expected) = expected
        && &schema != expected
    {
        let differs = expected
            .iter()
            .find(|(n, s)| schema.get(*n) != Some(s))
            .map(|(n, s)| format!("{n}: {:?} here, {s:?} in the run's weights", schema.get(n)))
            .or_else(|| {
                schema.keys().find(|n| !expected.contains_key(*n)).map(|n| format!("unknown tensor {n}"))
            })
            .unwrap_or_default();
        return Err(bad("schema_mismatch", differs));
    }
    Ok(schema)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn body(tensors: &[(&str, Vec<usize>, Vec<f32>)]) -> Vec<u8> {
        let bytes: Vec<(String, Vec<usize>, Vec<u8>)> = tensors
            .iter()
            .map(|(n, s, v)| (n.to_string(), s.clone(), v.iter().flat_map(|x| x.to_le_bytes()).collect()))
            .collect();
        let views: Vec<(String, safetensors::tensor::TensorView)> = bytes
            .iter()
            .map(|(n, s, b)| {
                (n.clone(), safetensors::tensor::TensorView::new(Dtype::F32, s.clone(), b).unwrap())
            })
            .collect();
        safetensors::serialize(views, None).unwrap()
    }

    #[test]
    fn good_bodies_pass_and_each_kind_of_bad_one_is_named() {
        let good = body(&[("a.w", vec![2, 2], vec![1.0, 2.0, 3.0, 4.0]), ("a.b", vec![2], vec![0.5, -0.5])]);
        let schema = check_body(&good, None).unwrap();
        assert_eq!(schema["a.w"], vec![2, 2]);
        assert_eq!(check_body(&good, Some(&schema)).unwrap(), schema);
        let reason = |b: &[u8], s: Option<&Schema>| check_body(b, s).unwrap_err().reason;
        // A header length far beyond the body (the forged frame that once stopped a run).
        let mut forged = vec![0xff; 8];
        forged.extend_from_slice(b"{}");
        assert_eq!(reason(&forged, None), "bad_safetensors");
        assert_eq!(reason(&good[..good.len() - 3], None), "bad_safetensors");
        let nan = body(&[("a.w", vec![2, 2], vec![1.0, f32::NAN, 3.0, 4.0]), ("a.b", vec![2], vec![0.0; 2])]);
        assert_eq!(reason(&nan, Some(&schema)), "non_finite");
        let reshaped = body(&[("a.w", vec![4, 1], vec![1.0; 4]), ("a.b", vec![2], vec![0.0; 2])]);
        let err = check_body(&reshaped, Some(&schema)).unwrap_err();
        assert_eq!(err.reason, "schema_mismatch");
        assert!(err.detail.contains("a.w"), "{}", err.detail);
        let extra = body(&[
            ("a.w", vec![2, 2], vec![1.0; 4]),
            ("a.b", vec![2], vec![0.0; 2]),
            ("x", vec![1], vec![0.0]),
        ]);
        assert!(check_body(&extra, Some(&schema)).unwrap_err().detail.contains("unknown tensor x"));
        assert_eq!(reason(&body(&[]), None), "bad_safetensors");
    }
}
