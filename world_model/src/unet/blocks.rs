//! Building blocks of the DriftWorld U-Net (spec §5), on video tensors laid out
//! channel-first as `[b, c, f, h, w]` (f = frames).
//!
//! - [`Conv3dF`]: a factorised 3-D convolution: a 2-D k×k convolution per frame,
//!   then (k > 1) a temporal 1-D convolution over frames with zero padding on both
//!   sides, initialised to the identity (Dirac) with zero bias;
//! - [`ResBlock`]: GN → SiLU → conv, per-frame FiLM from the action embedding,
//!   GN → FiLM → SiLU → conv, plus a (1×1) skip;
//! - [`Attention`]: spatial self-attention inside each frame.
//!
//! GroupNorm statistics span the whole clip (channels-in-group × f × h × w), as
//! PyTorch's GroupNorm does on a 5-D tensor.

use burn::module::{Module, Param};
use burn::nn::conv::{Conv1d, Conv1dConfig, Conv2d, Conv2dConfig};
use burn::nn::{GroupNorm, GroupNormConfig, Linear, LinearConfig, PaddingConfig1d, PaddingConfig2d};
use burn::tensor::activation::{silu, softmax};
use burn::tensor::{Device, Tensor, TensorData};

/// GroupNorm over a video: `[b, c, f, h, w]`, statistics over each group's
/// channels and all frames and pixels.
pub fn group_norm(norm: &GroupNorm, x: Tensor<5>) -> Tensor<5> {
    let [b, c, f, h, w] = x.dims();
    norm.forward(x.reshape([b, c, f * h * w])).reshape([b, c, f, h, w])
}

/// A factorised 3-D convolution (spatial k×k per frame, then temporal k over frames).
#[derive(Module, Debug)]
pub struct Conv3dF {
    pub(super) spatial: Conv2d,
    pub(super) temporal: Option<Conv1d>,
}

impl Conv3dF {
    /// `cin → cout` with kernel `k` and spatial stride `stride`.
    pub fn new(cin: usize, cout: usize, k: usize, stride: usize, device: &Device) -> Self {
        let p = k / 2;
        let spatial = Conv2dConfig::new([cin, cout], [k, k])
            .with_stride([stride, stride])
            .with_padding(PaddingConfig2d::Explicit(p, p, p, p))
            .init(device);
        let temporal = (k > 1).then(|| {
            let mut conv =
                Conv1dConfig::new(cout, cout, k).with_padding(PaddingConfig1d::Explicit(p, p)).init(device);
            // Dirac init: weight[c, c, k/2] = 1, everything else 0; zero bias.
            let mut dirac = vec![0f32; cout * cout * k];
            for c in 0..cout {
                dirac[(c * cout + c) * k + p] = 1.0;
            }
            conv.weight =
                Param::from_tensor(Tensor::from_data(TensorData::new(dirac, [cout, cout, k]), device));
            conv.bias = Some(Param::from_tensor(Tensor::zeros([cout], device)));
            conv
        });
        Self { spatial, temporal }
    }

    /// The same convolution reading `extra` more input channels, inserted before
    /// the last `after` existing ones (0: appended last), with zero weights, so its
    /// output is unchanged.
    pub fn with_extra_inputs(mut self, extra: usize, after: usize) -> Self {
        let w = self.spatial.weight.val(); // [cout, cin, k, k]
        let [co, ci, kh, kw] = w.dims();
        let zeros = Tensor::<4>::zeros([co, extra, kh, kw], &w.device());
        let split = ci - after.min(ci);
        let mut parts = Vec::with_capacity(3);
        if split > 0 {
            parts.push(w.clone().narrow(1, 0, split));
        }
        parts.push(zeros);
        if split < ci {
            parts.push(w.narrow(1, split, ci - split));
        }
        // Detached: a fresh leaf, so it can be a trainable parameter on an autodiff device.
        self.spatial.weight = Param::from_tensor(Tensor::cat(parts, 1).detach());
        self
    }

    /// # Shapes
    /// `[b, cin, f, h, w] -> [b, cout, f, h/stride, w/stride]`
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        let [b, c, f, h, w] = x.dims();
        let x = x.swap_dims(1, 2).reshape([b * f, c, h, w]); // [b f, c, h, w]
        let y = self.spatial.forward(x); // [b f, co, h', w']
        let [_, co, h2, w2] = y.dims();
        let y = y.reshape([b, f, co, h2, w2]);
        match &self.temporal {
            None => y.swap_dims(1, 2), // [b, co, f, h', w']
            Some(t) => {
                let z = y.permute([0, 3, 4, 2, 1]).reshape([b * h2 * w2, co, f]); // [b h w, co, f]
                let z = t.forward(z); // [b h w, co, f]
                z.reshape([b, h2, w2, co, f]).permute([0, 3, 4, 1, 2]) // [b, co, f, h', w']
            }
        }
    }
}

/// A residual block with per-frame FiLM conditioning.
#[derive(Module, Debug)]
pub struct ResBlock {
    pub(super) norm1: GroupNorm,
    pub(super) conv1: Conv3dF,
    pub(super) film: Linear,
    pub(super) norm2: GroupNorm,
    pub(super) conv2: Conv3dF,
    pub(super) skip: Option<Conv3dF>,
}

impl ResBlock {
    /// `cin → cout`, conditioned on an embedding of size `emb`.
    pub fn new(cin: usize, cout: usize, emb: usize, groups: usize, device: &Device) -> Self {
        Self {
            norm1: GroupNormConfig::new(groups, cin).init(device),
            conv1: Conv3dF::new(cin, cout, 3, 1, device),
            film: LinearConfig::new(emb, 2 * cout).init(device),
            norm2: GroupNormConfig::new(groups, cout).init(device),
            conv2: Conv3dF::new(cout, cout, 3, 1, device),
            skip: (cin != cout).then(|| Conv3dF::new(cin, cout, 1, 1, device)),
        }
    }

    /// # Shapes
    /// - `x`: `[b, cin, f, h, w]`
    /// - `emb`: `[b, f, e]` (one embedding per frame)
    /// - returns `[b, cout, f, h, w]`
    pub fn forward(&self, x: Tensor<5>, emb: Tensor<3>) -> Tensor<5> {
        let h = self.conv1.forward(silu(group_norm(&self.norm1, x.clone()))); // [b, co, f, h, w]
        let [b, co, f, _, _] = h.dims();
        let ss = self.film.forward(silu(emb)); // [b, f, 2 co]
        let ss = ss.swap_dims(1, 2).reshape([b, 2 * co, f, 1, 1]); // [b, 2 co, f, 1, 1]
        let scale = ss.clone().narrow(1, 0, co);
        let shift = ss.narrow(1, co, co);
        let h = group_norm(&self.norm2, h) * (scale + 1.0) + shift;
        let h = self.conv2.forward(silu(h));
        let skip = match &self.skip {
            Some(s) => s.forward(x),
            None => x,
        };
        skip + h
    }
}

/// Spatial self-attention within each frame: `x + proj(MHA(qkv(GN(x))))`.
#[derive(Module, Debug)]
pub struct Attention {
    pub(super) norm: GroupNorm,
    pub(super) qkv: Conv1d,
    pub(super) proj: Conv1d,
    pub(super) heads: usize,
}

impl Attention {
    /// Over `c` channels with heads of `head_dim` channels.
    pub fn new(c: usize, head_dim: usize, groups: usize, device: &Device) -> Self {
        Self {
            norm: GroupNormConfig::new(groups, c).init(device),
            qkv: Conv1dConfig::new(c, 3 * c, 1).init(device),
            proj: Conv1dConfig::new(c, c, 1).init(device),
            heads: (c / head_dim.max(1)).max(1),
        }
    }

    /// # Shapes
    /// `[b, c, f, h, w] -> [b, c, f, h, w]`
    pub fn forward(&self, x: Tensor<5>) -> Tensor<5> {
        self.forward_normed(x, false)
    }

    /// [`Self::forward`] with the GroupNorm statistics taken per frame (`per_frame`, as
    /// the official DriftWorld code does) or over the whole clip.
    ///
    /// # Shapes
    /// `[b, c, f, h, w] -> [b, c, f, h, w]`
    pub fn forward_normed(&self, x: Tensor<5>, per_frame: bool) -> Tensor<5> {
        let [b, c, f, h, w] = x.dims();
        let t = h * w;
        let (n, d) = (self.heads, c / self.heads);
        let y = if per_frame {
            self.norm.forward(x.clone().swap_dims(1, 2).reshape([b * f, c, t])) // [b f, c, t]
        } else {
            group_norm(&self.norm, x.clone()).swap_dims(1, 2).reshape([b * f, c, t]) // [b f, c, t]
        };
        let qkv = self.qkv.forward(y); // [b f, 3c, t]
        let split = |i: usize| qkv.clone().narrow(1, i * c, c).reshape([b * f * n, d, t]); // [b f n, d, t]
        let (q, k, v) = (split(0), split(1), split(2));
        // q and k each scaled by d^(-1/4): logits scaled by 1/sqrt(d) in total.
        let s = (d as f64).powf(-0.25);
        let logits = (q * s).swap_dims(1, 2).matmul(k * s); // [b f n, t, t]
        let attn = softmax(logits, 2);
        let o = v.matmul(attn.swap_dims(1, 2)); // [b f n, d, t]
        let o = self.proj.forward(o.reshape([b * f, c, t])); // [b f, c, t]
        x + o.reshape([b, f, c, h, w]).swap_dims(1, 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn temporal_conv_starts_as_identity() {
        // With the Dirac temporal init, Conv3dF equals its spatial conv applied per frame.
        let device = Device::flex();
        let conv = Conv3dF::new(2, 3, 3, 1, &device);
        let x = Tensor::<5>::random([1, 2, 4, 5, 5], burn::tensor::Distribution::Default, &device);
        let full = conv.forward(x.clone());
        let spatial_only = Conv3dF { spatial: conv.spatial.clone(), temporal: None }.forward(x);
        let diff: f32 = (full - spatial_only).abs().max().into_scalar();
        assert!(diff < 1e-6, "{diff}");
    }

    #[test]
    fn parameter_counts_match_the_spec_units() {
        // Spec §5: Conv3d 96→96 = 110,784; ResBlock 96→96 = 271,296 and 192→96 = 372,960
        // (with a 256-d embedding, 32 groups); Attn(96) = 37,440.
        let device = Device::flex();
        assert_eq!(Conv3dF::new(96, 96, 3, 1, &device).num_params(), 110_784);
        assert_eq!(ResBlock::new(96, 96, 256, 32, &device).num_params(), 271_296);
        assert_eq!(ResBlock::new(192, 96, 256, 32, &device).num_params(), 372_960);
        assert_eq!(Attention::new(96, 8, 32, &device).num_params(), 37_440);
    }
}
