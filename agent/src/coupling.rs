//! One conditional affine coupling layer of the real-NVP bijector (`docs/sac-lsp.md` §1; Dinh et al. 2017,
//! "Density estimation using Real NVP", sections 3.2-3.3).
//!
//! x = [A, B], A = x[..D/2], B = x[D/2..]. The odd layer keeps B and maps A' = A * exp(s([B, c])) +
//! t([B, c]); the even layer keeps A and maps B' likewise. s and t are separate MLPs on the
//! concatenation of the kept half and the observation embedding c (tanh hidden, linear output,
//! Xavier weights, N(0, 1) biases). The scale is raw exp(s): no tanh, no clipping, no regulariser.
//!
//! For a 1-d action (D = 1) the first half is empty: the odd layer has nothing to move and is the
//! identity (no parameters), and the even layer's s and t see only c, i.e. a conditional affine map
//! of the Gaussian latent. That keeps `InvertedPendulum` (one force) in reach of the same policy.

use candle_core::{Result, Tensor};
use candle_nn::VarBuilder;

use crate::mlp::{Activation, BiasInit, Grad, Mlp, MlpSpec};

/// Which half a coupling layer transforms (names as in `real_nvp_bijector.py`'s layer order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Parity {
    /// Transforms the first half A, conditioned on B (layers 1, 3, ...).
    Odd,
    /// Transforms the second half B, conditioned on A (layers 2, 4, ...).
    Even,
}

impl Parity {
    /// Parity of 0-based layer `index`: odd, even, odd, ...
    pub fn of_layer(index: usize) -> Self {
        if index.is_multiple_of(2) { Self::Odd } else { Self::Even }
    }
}

/// Shape of a [`Coupling`].
#[derive(Clone, Debug, PartialEq)]
pub struct CouplingSpec<'a> {
    /// Which half is transformed.
    pub parity: Parity,
    /// Dimension D of x.
    pub dim: usize,
    /// Dimension of the conditioning embedding c.
    pub context_dim: usize,
    /// Hidden widths (tanh) of the s and t nets.
    pub hidden: &'a [usize],
}

/// Output of a coupling pass: the mapped tensor and log|det| of that direction's Jacobian.
#[derive(Clone, Debug)]
pub struct CouplingOutput {
    /// Mapped tensor, `[batch, D]`.
    pub output: Tensor,
    /// log|det d output / d input|, `[batch]`: sum s forward, -sum s inverse.
    pub log_det: Tensor,
}

/// A conditional affine coupling layer: parameters under `scale.*` and `translation.*`.
#[derive(Clone, Debug)]
pub struct Coupling {
    parity: Parity,
    split: usize,
    dim: usize,
    /// The s and t nets; `None` when the moved half is empty (the layer is the identity).
    nets: Option<ScaleTranslation>,
}

#[derive(Clone, Debug)]
struct ScaleTranslation {
    scale: Mlp,
    translation: Mlp,
}

impl Coupling {
    /// Builds the s and t nets under `vb.pp("scale")` and `vb.pp("translation")`.
    pub fn new(spec: &CouplingSpec, vb: VarBuilder) -> Result<Self> {
        let split = spec.dim / 2;
        let (kept, moved) = match spec.parity {
            Parity::Odd => (spec.dim - split, split),
            Parity::Even => (split, spec.dim - split),
        };
        if moved == 0 {
            return Ok(Self { parity: spec.parity, split, dim: spec.dim, nets: None });
        }
        let mut layers = spec.hidden.to_vec();
        layers.push(moved);
        let inputs = [("x", kept + spec.context_dim)];
        let net = MlpSpec {
            inputs: &inputs,
            layers: &layers,
            hidden: Activation::Tanh,
            output: Activation::Linear,
            bias: BiasInit::StandardNormal,
        };
        let scale = Mlp::new(&net, vb.pp("scale"))?;
        let translation = Mlp::new(&net, vb.pp("translation"))?;
        Ok(Self {
            parity: spec.parity,
            split,
            dim: spec.dim,
            nets: Some(ScaleTranslation { scale, translation }),
        })
    }

    /// (kept half, moved half) of x.
    fn halves(&self, x: &Tensor) -> Result<(Tensor, Tensor)> {
        let a = x.narrow(1, 0, self.split)?;
        let b = x.narrow(1, self.split, self.dim - self.split)?;
        Ok(match self.parity {
            Parity::Odd => (b, a),
            Parity::Even => (a, b),
        })
    }

    fn join(&self, kept: &Tensor, moved: &Tensor) -> Result<Tensor> {
        if kept.dim(1)? == 0 {
            return Ok(moved.clone());
        }
        match self.parity {
            Parity::Odd => Tensor::cat(&[moved, kept], 1),
            Parity::Even => Tensor::cat(&[kept, moved], 1),
        }
    }

    fn scale_and_translation(
        nets: &ScaleTranslation,
        kept: &Tensor,
        context: &Tensor,
        grad: Grad,
    ) -> Result<(Tensor, Tensor)> {
        let input = if kept.dim(1)? == 0 { context.clone() } else { Tensor::cat(&[kept, context], 1)? };
        Ok((nets.scale.forward(&[&input], grad)?, nets.translation.forward(&[&input], grad)?))
    }

    /// The identity layer's output (nothing to move): x itself, log|det| = 0.
    fn identity(x: &Tensor) -> Result<CouplingOutput> {
        let log_det = Tensor::zeros(x.dim(0)?, x.dtype(), x.device())?;
        Ok(CouplingOutput { output: x.clone(), log_det })
    }

    /// Forward map: moved' = moved * exp(s) + t; log|det| = sum s.
    pub fn forward(&self, x: &Tensor, context: &Tensor, grad: Grad) -> Result<CouplingOutput> {
        let Some(nets) = &self.nets else { return Self::identity(x) };
        let (kept, moved) = self.halves(x)?;
        let (s, t) = Self::scale_and_translation(nets, &kept, context, grad)?;
        let moved = (moved * s.exp()?)?.add(&t)?;
        Ok(CouplingOutput { output: self.join(&kept, &moved)?, log_det: s.sum(1)? })
    }

    /// Inverse map: moved = (moved' - t) * exp(-s), s and t from the unchanged half; log|det| = -sum s.
    pub fn inverse(&self, y: &Tensor, context: &Tensor, grad: Grad) -> Result<CouplingOutput> {
        let Some(nets) = &self.nets else { return Self::identity(y) };
        let (kept, moved) = self.halves(y)?;
        let (s, t) = Self::scale_and_translation(nets, &kept, context, grad)?;
        let moved = (moved - t)?.mul(&s.neg()?.exp()?)?;
        Ok(CouplingOutput { output: self.join(&kept, &moved)?, log_det: s.sum(1)?.neg()? })
    }
}
