//! The diffusion policy's networks (Chi et al. 2023, as used by DriftWorld §10),
//! scaled down for a CPU:
//!
//! - [`ObsEncoder`]: a ResNet-style CNN with GroupNorm (no BatchNorm, so a
//!   batch of one behaves like a batch of many) from a 96x96 frame to a feature
//!   vector; the last 6x6 map is flattened, not pooled, so where the block and
//!   the goal are survives;
//! - [`CondUnet1d`]: the conditional 1-D U-Net over the action sequence, with
//!   FiLM from (diffusion-step embedding, observation features) in every block.

use burn::config::Config;
use burn::module::Module;
use burn::nn::conv::{Conv1d, Conv1dConfig, Conv2d, Conv2dConfig, ConvTranspose1d, ConvTranspose1dConfig};
use burn::nn::{GroupNorm, GroupNormConfig, Linear, LinearConfig, PaddingConfig1d, PaddingConfig2d};
use burn::tensor::activation::{mish, silu};
use burn::tensor::{Device, Tensor};

/// Network sizes.
#[derive(Config, Debug, PartialEq)]
pub struct NetConfig {
    /// Image side.
    #[config(default = 96)]
    pub image_size: usize,
    /// Encoder width (channels at 48², doubled at 24², quadrupled at 12² and 6²).
    #[config(default = 16)]
    pub encoder_width: usize,
    /// Feature size per frame.
    #[config(default = 128)]
    pub feature_dim: usize,
    /// U-Net channels per level.
    #[config(default = "vec![64, 128, 256]")]
    pub down_dims: Vec<usize>,
    /// 1-D kernel size.
    #[config(default = 5)]
    pub kernel: usize,
    /// Diffusion-step embedding size.
    #[config(default = 64)]
    pub step_embed: usize,
    /// Observation frames.
    #[config(default = 2)]
    pub obs_horizon: usize,
    /// Action dimension.
    #[config(default = 2)]
    pub action_dim: usize,
    /// Entries of the proprioceptive vector (absent: the action dimension, as for
    /// Push-T, where both are a 2-D position).
    pub proprio_dim: Option<usize>,
}

impl NetConfig {
    /// Entries of the proprioceptive vector read with each frame.
    pub fn proprio(&self) -> usize {
        self.proprio_dim.unwrap_or(self.action_dim)
    }

    /// Conditioning size: per obs frame, features + proprioception.
    pub fn obs_cond_dim(&self) -> usize {
        self.obs_horizon * (self.feature_dim + self.proprio())
    }
}

fn conv2(cin: usize, cout: usize, stride: usize, device: &Device) -> Conv2d {
    Conv2dConfig::new([cin, cout], [3, 3])
        .with_stride([stride, stride])
        .with_padding(PaddingConfig2d::Explicit(1, 1, 1, 1))
        .init(device)
}

/// GN → SiLU → conv, twice, plus the input.
#[derive(Module, Debug)]
pub struct Res2d {
    pub(crate) n1: GroupNorm,
    pub(crate) c1: Conv2d,
    pub(crate) n2: GroupNorm,
    pub(crate) c2: Conv2d,
}

impl Res2d {
    fn new(c: usize, device: &Device) -> Self {
        let g = (c / 8).max(1);
        Self {
            n1: GroupNormConfig::new(g, c).init(device),
            c1: conv2(c, c, 1, device),
            n2: GroupNormConfig::new(g, c).init(device),
            c2: conv2(c, c, 1, device),
        }
    }

    fn forward(&self, x: Tensor<4>) -> Tensor<4> {
        let h = self.c1.forward(silu(self.n1.forward(x.clone())));
        x + self.c2.forward(silu(self.n2.forward(h)))
    }
}

/// Frame encoder: 96² → 48² → 24² → 12² → 6², flattened, linear.
#[derive(Module, Debug)]
pub struct ObsEncoder {
    pub(crate) downs: Vec<Conv2d>,
    pub(crate) blocks: Vec<Res2d>,
    pub(crate) norm: GroupNorm,
    pub(crate) out: Linear,
}

impl ObsEncoder {
    /// Builds the encoder.
    pub fn new(cfg: &NetConfig, device: &Device) -> Self {
        let w = cfg.encoder_width;
        let chans = [3, w, 2 * w, 4 * w, 4 * w];
        let downs = (0..4).map(|i| conv2(chans[i], chans[i + 1], 2, device)).collect();
        let blocks = (1..4).map(|i| Res2d::new(chans[i], device)).collect();
        let side = cfg.image_size / 16;
        Self {
            downs,
            blocks,
            norm: GroupNormConfig::new((4 * w / 8).max(1), 4 * w).init(device),
            out: LinearConfig::new(4 * w * side * side, cfg.feature_dim).init(device),
        }
    }

    /// # Shapes
    /// `[n, 3, 96, 96]` in [-1, 1] → `[n, feature_dim]`
    pub fn forward(&self, x: Tensor<4>) -> Tensor<2> {
        let mut h = x;
        for (i, down) in self.downs.iter().enumerate() {
            h = down.forward(h); // 48², 24², 12², 6²
            if let Some(b) = self.blocks.get(i) {
                h = b.forward(h);
            }
        }
        let h = silu(self.norm.forward(h)); // [n, 4w, 6, 6]
        let [n, c, s, _] = h.dims();
        self.out.forward(h.reshape([n, c * s * s]))
    }
}

/// Conv1d → GroupNorm(8) → Mish.
#[derive(Module, Debug)]
pub struct Conv1dBlock {
    pub(crate) conv: Conv1d,
    pub(crate) norm: GroupNorm,
}

impl Conv1dBlock {
    fn new(cin: usize, cout: usize, k: usize, device: &Device) -> Self {
        Self {
            conv: Conv1dConfig::new(cin, cout, k)
                .with_padding(PaddingConfig1d::Explicit(k / 2, k / 2))
                .init(device),
            norm: GroupNormConfig::new(8.min(cout), cout).init(device),
        }
    }

    fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        mish(self.norm.forward(self.conv.forward(x)))
    }
}

/// Conditional residual block: block, FiLM(cond), block, plus a 1x1 skip.
#[derive(Module, Debug)]
pub struct CondRes1d {
    pub(crate) b0: Conv1dBlock,
    pub(crate) film: Linear,
    pub(crate) b1: Conv1dBlock,
    pub(crate) skip: Option<Conv1d>,
}

impl CondRes1d {
    fn new(cin: usize, cout: usize, cond: usize, k: usize, device: &Device) -> Self {
        Self {
            b0: Conv1dBlock::new(cin, cout, k, device),
            film: LinearConfig::new(cond, 2 * cout).init(device),
            b1: Conv1dBlock::new(cout, cout, k, device),
            skip: (cin != cout).then(|| Conv1dConfig::new(cin, cout, 1).init(device)),
        }
    }

    /// `x: [b, cin, t]`, `cond: [b, cond]` → `[b, cout, t]`
    fn forward(&self, x: Tensor<3>, cond: Tensor<2>) -> Tensor<3> {
        let h = self.b0.forward(x.clone()); // [b, co, t]
        let [b, co, _] = h.dims();
        let ss = self.film.forward(mish(cond)).reshape([b, 2 * co, 1]);
        let h = h * ss.clone().narrow(1, 0, co) + ss.narrow(1, co, co);
        let h = self.b1.forward(h);
        let skip = match &self.skip {
            Some(s) => s.forward(x),
            None => x,
        };
        h + skip
    }
}

/// A U-Net level: two conditional blocks and an optional resampling.
#[derive(Module, Debug)]
pub struct Level1d {
    pub(crate) r0: CondRes1d,
    pub(crate) r1: CondRes1d,
    pub(crate) down: Option<Conv1d>,
    pub(crate) up: Option<ConvTranspose1d>,
}

/// The conditional 1-D U-Net (ε-prediction).
#[derive(Module, Debug)]
pub struct CondUnet1d {
    pub(crate) step1: Linear,
    pub(crate) step2: Linear,
    pub(crate) downs: Vec<Level1d>,
    pub(crate) mids: Vec<CondRes1d>,
    pub(crate) ups: Vec<Level1d>,
    pub(crate) final_block: Conv1dBlock,
    pub(crate) final_conv: Conv1d,
    pub(crate) step_embed: usize,
}

impl CondUnet1d {
    /// Builds the U-Net.
    pub fn new(cfg: &NetConfig, device: &Device) -> Self {
        let (k, e) = (cfg.kernel, cfg.step_embed);
        let cond = e + cfg.obs_cond_dim();
        let mut dims = vec![cfg.action_dim];
        dims.extend(&cfg.down_dims);
        let pairs: Vec<(usize, usize)> = dims.windows(2).map(|w| (w[0], w[1])).collect();
        let n = pairs.len();
        let downs = pairs
            .iter()
            .enumerate()
            .map(|(i, &(a, b))| Level1d {
                r0: CondRes1d::new(a, b, cond, k, device),
                r1: CondRes1d::new(b, b, cond, k, device),
                down: (i + 1 < n).then(|| {
                    Conv1dConfig::new(b, b, 3)
                        .with_stride(2)
                        .with_padding(PaddingConfig1d::Explicit(1, 1))
                        .init(device)
                }),
                up: None,
            })
            .collect();
        let mid = *cfg.down_dims.last().unwrap_or(&64);
        let mids = vec![CondRes1d::new(mid, mid, cond, k, device), CondRes1d::new(mid, mid, cond, k, device)];
        let ups = pairs[1..]
            .iter()
            .rev()
            .map(|&(a, b)| Level1d {
                r0: CondRes1d::new(2 * b, a, cond, k, device),
                r1: CondRes1d::new(a, a, cond, k, device),
                down: None,
                up: Some(ConvTranspose1dConfig::new([a, a], 4).with_stride(2).with_padding(1).init(device)),
            })
            .collect();
        let first = cfg.down_dims[0];
        Self {
            step1: LinearConfig::new(e, 4 * e).init(device),
            step2: LinearConfig::new(4 * e, e).init(device),
            downs,
            mids,
            ups,
            final_block: Conv1dBlock::new(first, first, k, device),
            final_conv: Conv1dConfig::new(first, cfg.action_dim, 1).init(device),
            step_embed: e,
        }
    }

    /// Predicts the noise of a noisy action sequence.
    ///
    /// # Shapes
    /// - `x`: `[b, horizon, action_dim]`; `t`: `[b]` diffusion steps (0..T); `obs`: `[b, obs_cond]`
    /// - returns `[b, horizon, action_dim]`
    pub fn forward(&self, x: Tensor<3>, t: Tensor<1>, obs: Tensor<2>) -> Tensor<3> {
        let te = self.step2.forward(mish(self.step1.forward(sinusoidal(t, self.step_embed)))); // [b, e]
        let cond = Tensor::cat(vec![te, obs], 1); // [b, cond]
        let mut h = x.swap_dims(1, 2); // [b, a, horizon]
        let mut skips = Vec::new();
        for l in &self.downs {
            h = l.r1.forward(l.r0.forward(h, cond.clone()), cond.clone());
            skips.push(h.clone());
            if let Some(d) = &l.down {
                h = d.forward(h); // horizon / 2
            }
        }
        for m in &self.mids {
            h = m.forward(h, cond.clone());
        }
        for l in &self.ups {
            let skip = skips.pop().unwrap_or_else(|| h.clone());
            h = l.r1.forward(l.r0.forward(Tensor::cat(vec![h, skip], 1), cond.clone()), cond.clone());
            if let Some(u) = &l.up {
                h = u.forward(h); // horizon x 2
            }
        }
        self.final_conv.forward(self.final_block.forward(h)).swap_dims(1, 2)
    }
}

/// Sinusoidal embedding of diffusion steps, `[b] -> [b, dim]`.
fn sinusoidal(t: Tensor<1>, dim: usize) -> Tensor<2> {
    let half = dim / 2;
    let device = t.device();
    let freqs: Vec<f32> =
        (0..half).map(|i| (-(10000f32).ln() * i as f32 / (half - 1).max(1) as f32).exp()).collect();
    let freqs = Tensor::<1>::from_floats(freqs.as_slice(), &device).reshape([1, half]);
    let [b] = t.dims();
    let args = t.reshape([b, 1]) * freqs;
    Tensor::cat(vec![args.clone().sin(), args.cos()], 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes() {
        let device = Device::flex();
        let cfg = NetConfig::new();
        let enc = ObsEncoder::new(&cfg, &device);
        assert_eq!(enc.forward(Tensor::zeros([3, 3, 96, 96], &device)).dims(), [3, 128]);
        let unet = CondUnet1d::new(&cfg, &device);
        let y = unet.forward(
            Tensor::zeros([2, 16, 2], &device),
            Tensor::from_floats([3.0, 50.0], &device),
            Tensor::zeros([2, cfg.obs_cond_dim()], &device),
        );
        assert_eq!(y.dims(), [2, 16, 2]);
    }
}
