//! Fully connected layers and MLPs, initialised as `haarnoja/sac` does (`docs/sac-lsp.md` §11).
//!
//! Weights are Xavier/Glorot-uniform with limit sqrt(6 / (fan_in + fan_out)). A multi-input first
//! layer (`MLPFunction` in `sac/misc/mlp.py`) has one weight matrix per input, each Xavier-initialised
//! with its own fan-in, summed with one bias: equal to a layer on the concatenation, but initialised
//! differently. Weights are stored `[out, in]` as in candle and PyTorch.

use candle_core::{Result, Tensor};
use candle_nn::{Init, VarBuilder};

/// Nonlinearity after a layer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activation {
    /// max(x, 0).
    Relu,
    /// tanh(x).
    Tanh,
    /// Identity.
    Linear,
}

impl Activation {
    fn apply(self, x: Tensor) -> Result<Tensor> {
        match self {
            Self::Relu => x.relu(),
            Self::Tanh => x.tanh(),
            Self::Linear => Ok(x),
        }
    }
}

/// How biases start: zero (critics, embedding) or N(0, 1) (coupling s/t nets, `tf.random_normal`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BiasInit {
    /// All zeros.
    Zero,
    /// Standard normal.
    StandardNormal,
}

impl BiasInit {
    fn init(self) -> Init {
        match self {
            Self::Zero => Init::Const(0.0),
            Self::StandardNormal => Init::Randn { mean: 0.0, stdev: 1.0 },
        }
    }
}

/// Xavier/Glorot-uniform limit sqrt(6 / (fan_in + fan_out)).
pub fn xavier_limit(fan_in: usize, fan_out: usize) -> f64 {
    (6.0 / (fan_in + fan_out) as f64).sqrt()
}

fn xavier(vb: &VarBuilder, name: &str, fan_in: usize, fan_out: usize) -> Result<Tensor> {
    let l = xavier_limit(fan_in, fan_out);
    vb.get_with_hints((fan_out, fan_in), name, Init::Uniform { lo: -l, up: l })
}

/// Whether a forward pass may send gradients into the layer's own parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grad {
    /// Track the parameters (training).
    Track,
    /// Use the parameters as constants; gradients still flow into the inputs. Used where a loss
    /// must not train a network it evaluates (Q inside the reparameterised policy loss).
    Frozen,
}

fn param(t: &Tensor, grad: Grad) -> Tensor {
    match grad {
        Grad::Track => t.clone(),
        Grad::Frozen => t.detach(),
    }
}

/// A dense layer y = sum_i x_i W_i^T + b with one weight matrix per input (one input: ordinary).
#[derive(Clone, Debug)]
pub struct Dense {
    weights: Vec<Tensor>,
    bias: Tensor,
}

impl Dense {
    /// A layer with inputs `inputs = [(name, width)]`: weights `weight` (one input) or
    /// `weight_{name}` (several), and `bias`.
    pub fn new(inputs: &[(&str, usize)], out: usize, bias: BiasInit, vb: VarBuilder) -> Result<Self> {
        let weights = match inputs {
            [(_, width)] => vec![xavier(&vb, "weight", *width, out)?],
            _ => inputs
                .iter()
                .map(|(name, width)| xavier(&vb, &format!("weight_{name}"), *width, out))
                .collect::<Result<_>>()?,
        };
        let bias = vb.get_with_hints(out, "bias", bias.init())?;
        Ok(Self { weights, bias })
    }

    /// Applies the layer to one tensor `[batch, in]` per input.
    pub fn forward(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        if xs.len() != self.weights.len() {
            candle_core::bail!("dense layer takes {} inputs, got {}", self.weights.len(), xs.len());
        }
        let mut acc: Option<Tensor> = None;
        for (x, w) in xs.iter().zip(&self.weights) {
            let y = x.matmul(&param(w, grad).t()?)?;
            acc = Some(match acc {
                None => y,
                Some(a) => (a + y)?,
            });
        }
        let acc = acc.ok_or_else(|| candle_core::Error::Msg("dense layer without inputs".into()))?;
        acc.broadcast_add(&param(&self.bias, grad))
    }
}

/// Shape of an [`Mlp`].
#[derive(Clone, Debug, PartialEq)]
pub struct MlpSpec<'a> {
    /// Named inputs of the first layer and their widths.
    pub inputs: &'a [(&'a str, usize)],
    /// Widths of all layers, the last being the output.
    pub layers: &'a [usize],
    /// Activation after every layer but the last.
    pub hidden: Activation,
    /// Activation after the last layer.
    pub output: Activation,
    /// Bias initialisation of every layer.
    pub bias: BiasInit,
}

/// A multilayer perceptron; layer k's parameters live under `layer{k}`.
#[derive(Clone, Debug)]
pub struct Mlp {
    layers: Vec<Dense>,
    hidden: Activation,
    output: Activation,
}

impl Mlp {
    /// Builds the layers under `vb.pp("layer{k}")`.
    pub fn new(spec: &MlpSpec, vb: VarBuilder) -> Result<Self> {
        let mut layers = Vec::with_capacity(spec.layers.len());
        let mut prev = 0;
        for (k, &out) in spec.layers.iter().enumerate() {
            let vb = vb.pp(format!("layer{k}"));
            let layer = if k == 0 {
                Dense::new(spec.inputs, out, spec.bias, vb)?
            } else {
                Dense::new(&[("x", prev)], out, spec.bias, vb)?
            };
            layers.push(layer);
            prev = out;
        }
        Ok(Self { layers, hidden: spec.hidden, output: spec.output })
    }

    /// Applies the MLP to its inputs (one `[batch, width]` tensor per named input).
    pub fn forward(&self, xs: &[&Tensor], grad: Grad) -> Result<Tensor> {
        let last = self.layers.len() - 1;
        let mut h = self.layers[0].forward(xs, grad)?;
        for (k, layer) in self.layers.iter().enumerate() {
            if k > 0 {
                h = layer.forward(&[&h], grad)?;
            }
            h = if k == last { self.output.apply(h)? } else { self.hidden.apply(h)? };
        }
        Ok(h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vars::SeededInit;
    use candle_core::{DType, Device};
    use candle_nn::VarMap;

    #[test]
    fn init_follows_xavier_with_per_input_fan_in_and_zero_bias() {
        let map = VarMap::new();
        let vb = SeededInit::new(3).builder(&map, DType::F32, &Device::Cpu);
        let spec = MlpSpec {
            inputs: &[("observation", 100), ("action", 8)],
            layers: &[128, 1],
            hidden: Activation::Relu,
            output: Activation::Linear,
            bias: BiasInit::Zero,
        };
        Mlp::new(&spec, vb).unwrap();
        let data = map.data().lock().unwrap();
        let max_abs =
            |n: &str| data[n].as_tensor().abs().unwrap().max_all().unwrap().to_scalar::<f32>().unwrap();
        let obs_w = max_abs("layer0.weight_observation") as f64;
        let act_w = max_abs("layer0.weight_action") as f64;
        assert!(obs_w <= xavier_limit(100, 128) && obs_w > 0.9 * xavier_limit(100, 128));
        assert!(act_w <= xavier_limit(8, 128) && act_w > 0.8 * xavier_limit(8, 128));
        assert_eq!(max_abs("layer0.bias"), 0.0);
        assert_eq!(data["layer1.weight"].shape().dims(), &[1, 128]);
    }
}
