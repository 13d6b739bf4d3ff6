//! The DriftWorld U-Net (spec §5): a factorised spatio-temporal U-Net that maps
//! noise, a history of K frames and F actions to F future frames in one pass.
//!
//! The history is flattened k-major into channels and broadcast over the F
//! future frames, then concatenated after the noise channels. Each future frame
//! f gets its own action embedding `e_f = MLP(a_f)`, applied by FiLM in every
//! residual block. There is no timestep input for the drifting objective; the
//! diffusion baseline adds a sinusoidal timestep embedding to `e_f`.
//! With `action_maps` (not in the paper) each future frame also gets one more
//! input channel: a Gaussian bump at its action's position in the frame, so the
//! convolutions see *where* the agent is driven, which FiLM (a per-channel
//! scale and shift) can only convey indirectly.
//! Skips follow the ADM layout: one after `conv_in`, one after every residual
//! block (with its attention) and one after every downsampling.

pub mod blocks;

use burn::config::Config;
use burn::module::Module;
use burn::nn::interpolate::{Interpolate2d, Interpolate2dConfig, InterpolateMode};
use burn::nn::{GroupNorm, GroupNormConfig, Linear, LinearConfig};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};

use blocks::{Attention, Conv3dF, ResBlock, group_norm};

/// U-Net hyper-parameters.
#[derive(Config, Debug, PartialEq)]
pub struct UNetConfig {
    /// Channels of one frame (3 in pixel space, C in latent space).
    pub frame_channels: usize,
    /// Context frames K.
    #[config(default = 4)]
    pub history: usize,
    /// Base channels.
    pub model_channels: usize,
    /// Channel multiplier per level.
    pub channel_mult: Vec<usize>,
    /// Residual blocks per level (the decoder has one more).
    #[config(default = 2)]
    pub res_blocks: usize,
    /// Downsampling rates (1, 2, 4, ...) whose levels get spatial attention.
    pub attention_rates: Vec<usize>,
    /// Channels per attention head.
    #[config(default = 8)]
    pub head_dim: usize,
    /// GroupNorm groups.
    #[config(default = 32)]
    pub groups: usize,
    /// Action dimension.
    #[config(default = 2)]
    pub action_dim: usize,
    /// Action (and timestep) embedding size.
    #[config(default = 256)]
    pub emb_dim: usize,
    /// Add a diffusion timestep embedding (the multi-step baseline).
    #[config(default = false)]
    pub timestep_embedding: bool,
    /// Feed each future frame's action as a Gaussian map at its position too
    /// (one more input channel; not in the paper). An option so that configs
    /// written before it existed still load (missing = none).
    #[config(default = "None")]
    pub action_maps: Option<bool>,
}

impl UNetConfig {
    /// Whether the U-Net reads action maps.
    pub fn uses_action_maps(&self) -> bool {
        self.action_maps == Some(true)
    }

    /// The paper's pixel-space Push-T model: 96x96 RGB, 96 channels, 4 levels,
    /// attention at 24² and 12² (8,375,201 parameters).
    pub fn pusht_pixel() -> Self {
        Self::new(3, 96, vec![1, 1, 1, 1], vec![4, 8])
    }

    /// The CPU default: on 12x12x8 autoencoder latents, 2 levels (12², 6²).
    pub fn pusht_latent(latent_channels: usize) -> Self {
        Self::new(latent_channels, 64, vec![1, 2], vec![2]).with_groups(16)
    }

    /// Builds the module.
    pub fn init(&self, device: &Device) -> UNet {
        let (e, g) = (self.emb_dim, self.groups);
        let mc = self.model_channels;
        let in_ch = self.frame_channels * (1 + self.history) + usize::from(self.uses_action_maps());
        let mut chans = vec![mc]; // channels of every skip, in push order
        let mut enc = Vec::new();
        let mut downs = Vec::new();
        let mut c = mc;
        let mut rate = 1;
        let levels = self.channel_mult.len();
        for (l, m) in self.channel_mult.iter().enumerate() {
            let co = m * mc;
            for _ in 0..self.res_blocks {
                let attn = self
                    .attention_rates
                    .contains(&rate)
                    .then(|| Attention::new(co, self.head_dim, g, device));
                enc.push(Level { res: ResBlock::new(c, co, e, g, device), attn });
                c = co;
                chans.push(c);
            }
            if l + 1 < levels {
                downs.push(Conv3dF::new(c, c, 3, 2, device));
                chans.push(c);
                rate *= 2;
            }
        }
        let mid = [ResBlock::new(c, c, e, g, device), ResBlock::new(c, c, e, g, device)];
        let mid_attn = Attention::new(c, self.head_dim, g, device);
        let mut dec = Vec::new();
        let mut ups = Vec::new();
        for (l, m) in self.channel_mult.iter().enumerate().rev() {
            let co = m * mc;
            for _ in 0..=self.res_blocks {
                let skip = chans.pop().unwrap_or(mc);
                let attn = self
                    .attention_rates
                    .contains(&rate)
                    .then(|| Attention::new(co, self.head_dim, g, device));
                dec.push(Level { res: ResBlock::new(c + skip, co, e, g, device), attn });
                c = co;
            }
            if l > 0 {
                ups.push(Conv3dF::new(c, c, 3, 1, device));
                rate /= 2;
            }
        }
        let time = self
            .timestep_embedding
            .then(|| [LinearConfig::new(e, e).init(device), LinearConfig::new(e, e).init(device)]);
        UNet {
            act1: LinearConfig::new(self.action_dim, e).init(device),
            act2: LinearConfig::new(e, e).init(device),
            time: time.map(|[a, b]| TimeMlp { l1: a, l2: b }),
            conv_in: Conv3dF::new(in_ch, mc, 3, 1, device),
            enc,
            downs,
            mid,
            mid_attn,
            dec,
            ups,
            upsample: Interpolate2dConfig::new()
                .with_scale_factor(Some([2.0, 2.0]))
                .with_mode(InterpolateMode::Nearest)
                .init(),
            norm_out: GroupNormConfig::new(g, c).init(device),
            conv_out: Conv3dF::new(c, self.frame_channels, 3, 1, device),
            res_blocks: self.res_blocks,
            emb_dim: e,
            action_maps: self.uses_action_maps(),
        }
    }
}

/// A residual block with optional attention after it.
#[derive(Module, Debug)]
pub struct Level {
    res: ResBlock,
    attn: Option<Attention>,
}

impl Level {
    fn forward(&self, x: Tensor<5>, emb: Tensor<3>) -> Tensor<5> {
        let h = self.res.forward(x, emb);
        match &self.attn {
            Some(a) => a.forward(h),
            None => h,
        }
    }
}

/// The timestep MLP of the diffusion baseline.
#[derive(Module, Debug)]
pub struct TimeMlp {
    l1: Linear,
    l2: Linear,
}

/// The U-Net.
#[derive(Module, Debug)]
pub struct UNet {
    act1: Linear,
    act2: Linear,
    time: Option<TimeMlp>,
    conv_in: Conv3dF,
    enc: Vec<Level>,
    downs: Vec<Conv3dF>,
    mid: [ResBlock; 2],
    mid_attn: Attention,
    dec: Vec<Level>,
    ups: Vec<Conv3dF>,
    upsample: Interpolate2d,
    norm_out: GroupNorm,
    conv_out: Conv3dF,
    res_blocks: usize,
    emb_dim: usize,
    action_maps: bool,
}

impl UNet {
    /// Predicts F future frames in one pass.
    ///
    /// # Shapes
    /// - `noise`: `[b, cf, F, h, w]`
    /// - `history`: `[b, cf, K, h, w]`
    /// - `actions`: `[b, F, a]` (a_{t+f} drives frame t+f+1)
    /// - `timestep`: `[b]` in [0, 1] (diffusion baseline only)
    /// - returns `[b, cf, F, h, w]`
    pub fn forward(
        &self,
        noise: Tensor<5>,
        history: Tensor<5>,
        actions: Tensor<3>,
        timestep: Option<Tensor<1>>,
    ) -> Tensor<5> {
        let [b, cf, f, h, w] = noise.dims();
        let [_, _, k, _, _] = history.dims();
        let hist = history.swap_dims(1, 2).reshape([b, k * cf, 1, h, w]).expand([b, k * cf, f, h, w]); // k-major
        let mut parts = vec![noise, hist]; // [b, cf, F, h, w], [b, cf K, F, h, w]
        if self.action_maps {
            parts.push(action_maps(actions.clone(), h, w)); // [b, 1, F, h, w]
        }
        let x = Tensor::cat(parts, 1); // [b, cf (1 + K) (+ 1), F, h, w]
        let mut emb = self.act2.forward(silu(self.act1.forward(actions))); // [b, F, e]
        if let (Some(mlp), Some(t)) = (&self.time, timestep) {
            let te = mlp.l2.forward(silu(mlp.l1.forward(sinusoidal(t, self.emb_dim)))); // [b, e]
            emb = emb + te.unsqueeze_dim::<3>(1);
        }
        let mut hcur = self.conv_in.forward(x); // [b, mc, F, h, w]
        let mut skips = vec![hcur.clone()];
        let levels = self.downs.len() + 1;
        for l in 0..levels {
            for i in 0..self.res_blocks {
                hcur = self.enc[l * self.res_blocks + i].forward(hcur, emb.clone());
                skips.push(hcur.clone());
            }
            if l + 1 < levels {
                hcur = self.downs[l].forward(hcur); // spatial / 2
                skips.push(hcur.clone());
            }
        }
        hcur = self.mid[0].forward(hcur, emb.clone());
        hcur = self.mid_attn.forward(hcur);
        hcur = self.mid[1].forward(hcur, emb.clone());
        let per = self.res_blocks + 1;
        for (k, _) in (0..levels).rev().enumerate() {
            for i in 0..per {
                let skip = skips.pop().unwrap_or_else(|| hcur.clone());
                hcur = self.dec[k * per + i].forward(Tensor::cat(vec![hcur, skip], 1), emb.clone());
            }
            if k + 1 < levels {
                hcur = self.ups[k].forward(self.up2(hcur)); // spatial x 2
            }
        }
        self.conv_out.forward(silu(group_norm(&self.norm_out, hcur)))
    }

    /// The same network with an action-map input channel added, its weights
    /// zero: it computes exactly what it did before, and training can then learn
    /// to use the maps (warm-starting an `action_maps` run from one without).
    pub fn with_action_maps(mut self) -> Self {
        if !self.action_maps {
            self.conv_in = self.conv_in.with_extra_inputs(1);
            self.action_maps = true;
        }
        self
    }

    /// Nearest-neighbour 2x upsampling in space.
    fn up2(&self, x: Tensor<5>) -> Tensor<5> {
        let [b, c, f, h, w] = x.dims();
        self.upsample.forward(x.reshape([b, c * f, h, w])).reshape([b, c, f, 2 * h, 2 * w])
    }
}

/// Standard deviation of an action map's bump, in world units (the world is
/// 512 wide; the agent's radius is 15).
pub const ACTION_MAP_SIGMA: f32 = 24.0;

/// A Gaussian bump per frame at the action's position, on an `h × w` grid over
/// the 512-unit world (row = y, column = x, as the renderer draws it). Actions
/// are normalised as `a' = 2a/511 − 1`.
///
/// # Shapes
/// `[b, F, 2] -> [b, 1, F, h, w]`
pub fn action_maps(actions: Tensor<3>, h: usize, w: usize) -> Tensor<5> {
    let [b, f, _] = actions.dims();
    let device = actions.device();
    let world = (actions + 1.0) * (511.0 / 2.0); // [b, F, 2] world units
    let axis = |n: usize, dim: usize| {
        let cells = n as f32 / 512.0; // grid cells per world unit
        let centre = world.clone().narrow(2, dim, 1).reshape([b, 1, f, 1, 1]) * cells; // [b, 1, F, 1, 1]
        let grid: Vec<f32> = (0..n).map(|j| j as f32 + 0.5).collect();
        let grid = Tensor::<1>::from_floats(grid.as_slice(), &device);
        let shape = if dim == 0 { [1, 1, 1, 1, n] } else { [1, 1, 1, n, 1] };
        let d = (grid.reshape(shape) - centre) / (ACTION_MAP_SIGMA * cells); // in sigmas
        d.clone() * d
    };
    let (dx, dy) = (axis(w, 0), axis(h, 1)); // [b, 1, F, 1, w], [b, 1, F, h, 1]
    (dx.expand([b, 1, f, h, w]) + dy.expand([b, 1, f, h, w])).mul_scalar(-0.5).exp()
}

/// Sinusoidal embedding of t ∈ [0, 1] (scaled by 1000), `[b] -> [b, dim]`.
fn sinusoidal(t: Tensor<1>, dim: usize) -> Tensor<2> {
    let half = dim / 2;
    let device = t.device();
    let freqs: Vec<f32> =
        (0..half).map(|i| (-(10000f32).ln() * i as f32 / half as f32).exp() * 1000.0).collect();
    let freqs = Tensor::<1>::from_floats(freqs.as_slice(), &device).reshape([1, half]);
    let [b] = t.dims();
    let args = t.reshape([b, 1]) * freqs; // [b, half]
    Tensor::cat(vec![args.clone().cos(), args.sin()], 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixel_config_has_the_papers_parameter_count() {
        // Spec §5: 66,560 + 40,800 + 2,652,480 + 580,032 + 5,032,512 + 2,817 = 8,375,201.
        let unet = UNetConfig::pusht_pixel().init(&Device::flex());
        assert_eq!(unet.num_params(), 8_375_201);
    }

    #[test]
    fn latent_model_predicts_four_frames_in_one_pass() {
        let device = Device::flex();
        let cfg = UNetConfig::pusht_latent(8);
        let unet = cfg.init(&device);
        let noise = Tensor::<5>::zeros([2, 8, 4, 12, 12], &device);
        let hist = Tensor::<5>::zeros([2, 8, 4, 12, 12], &device);
        let act = Tensor::<3>::zeros([2, 4, 2], &device);
        assert_eq!(unet.forward(noise.clone(), hist.clone(), act.clone(), None).dims(), [2, 8, 4, 12, 12]);
        // Fewer future frames (a truncated last chunk) work too: the temporal convs pad.
        let out = unet.forward(noise.narrow(2, 0, 3), hist, act.narrow(1, 0, 3), None);
        assert_eq!(out.dims(), [2, 8, 3, 12, 12]);
    }

    #[test]
    fn actions_condition_the_output() {
        let device = Device::flex();
        let unet = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(4) }.init(&device);
        let noise = Tensor::<5>::random([1, 4, 4, 12, 12], burn::tensor::Distribution::Default, &device);
        let hist = Tensor::<5>::random([1, 4, 4, 12, 12], burn::tensor::Distribution::Default, &device);
        let a = Tensor::<3>::zeros([1, 4, 2], &device);
        let y1 = unet.forward(noise.clone(), hist.clone(), a.clone(), None);
        let y2 = unet.forward(noise, hist, a + 0.5, None);
        let diff: f32 = (y1 - y2).abs().mean().into_scalar();
        assert!(diff > 1e-4, "actions have no effect ({diff})");
    }
}

#[cfg(test)]
mod action_map_tests {
    use super::*;

    #[test]
    fn action_map_peaks_at_the_actions_cell() {
        let device = Device::flex();
        // World (416, 96) on an 8x8 grid (64 units per cell): column 416/64 - 0.5 = 6,
        // row 96/64 - 0.5 = 1, both at a cell centre, so the bump is exactly 1 there.
        // Normalised: 2·416/511 − 1 and 2·96/511 − 1.
        let a = [2.0 * 416.0 / 511.0 - 1.0, 2.0 * 96.0 / 511.0 - 1.0];
        let act = Tensor::<1>::from_floats(a.as_slice(), &device).reshape([1, 1, 2]);
        let map: Vec<f32> = action_maps(act, 8, 8).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(map.len(), 64);
        assert!((map[8 + 6] - 1.0).abs() < 1e-5, "{}", map[8 + 6]);
        // One cell (64 units) to the right: exp(−(64/24)²/2) = exp(−3.556) = 0.0286.
        assert!((map[8 + 7] - 0.0286).abs() < 1e-3, "{}", map[8 + 7]);
        // One cell down is the same distance; one diagonal is exp(−7.111) = 0.00082.
        assert!((map[2 * 8 + 6] - 0.0286).abs() < 1e-3);
        assert!((map[2 * 8 + 7] - 0.00082).abs() < 1e-4);
        let max = map.iter().cloned().fold(f32::MIN, f32::max);
        assert_eq!(max, map[8 + 6]);
    }

    #[test]
    fn adding_action_maps_keeps_the_output_then_lets_actions_move_it() {
        let device = Device::flex();
        let cfg = UNetConfig { model_channels: 32, ..UNetConfig::pusht_latent(4) };
        let unet = cfg.init(&device);
        let rand = |s: [usize; 5]| Tensor::<5>::random(s, burn::tensor::Distribution::Default, &device);
        let (noise, hist) = (rand([1, 4, 4, 8, 8]), rand([1, 4, 4, 8, 8]));
        let a = Tensor::<3>::zeros([1, 4, 2], &device);
        let before = unet.forward(noise.clone(), hist.clone(), a.clone(), None);
        let widened = unet.with_action_maps();
        let after = widened.forward(noise.clone(), hist.clone(), a.clone(), None);
        let diff: f32 = (before - after.clone()).abs().max().into_scalar();
        assert!(diff < 1e-5, "widening changed the output by {diff}");
        // On an autodiff device the widened weight is a trainable leaf.
        let ad = device.clone().autodiff();
        let trained = cfg.init(&ad).with_action_maps();
        let y = trained.forward(noise.clone(), hist.clone(), a.clone(), None);
        let grads = burn::optim::GradientsParams::from_grads(y.sum().backward(), &trained);
        assert!(!grads.is_empty());
        // A fresh action-map model has the extra channel and reacts to it.
        let fresh = UNetConfig { action_maps: Some(true), ..cfg }.init(&device);
        assert_eq!(fresh.num_params(), widened.num_params());
        let y1 = fresh.forward(noise.clone(), hist.clone(), a.clone(), None);
        let y2 = fresh.forward(noise, hist, a + 0.5, None);
        let moved: f32 = (y1 - y2).abs().mean().into_scalar();
        assert!(moved > 1e-4, "actions have no effect ({moved})");
    }
}

#[cfg(test)]
mod timing {
    use super::*;
    use crate::drift::{PUSHT_TEMPERATURES, drift_loss};
    use burn::optim::{AdamWConfig, GradientsParams};

    /// One drifting training step on latents: 4 contexts x 16 samples = 64 clips.
    /// Run by hand: `cargo test --release -p world_model step_time -- --ignored --nocapture`
    /// (`UNET_BASE`, `CONTEXTS`, `SAMPLES` override 64, 4, 16).
    #[test]
    #[ignore = "timing, run by hand"]
    fn step_time() {
        let device = Device::flex().autodiff();
        let env = |k: &str, d: usize| std::env::var(k).ok().and_then(|v| v.parse().ok()).unwrap_or(d);
        let base = env("UNET_BASE", 64);
        let mut unet = UNetConfig { model_channels: base, ..UNetConfig::pusht_latent(8) }.init(&device);
        let mut optim = AdamWConfig::new().init();
        let (b, n, c) = (env("CONTEXTS", 4), env("SAMPLES", 16), 8);
        for i in 0..3 {
            let t0 = std::time::Instant::now();
            let noise = Tensor::<5>::random(
                [b * n, c, 4, 12, 12],
                burn::tensor::Distribution::Normal(0.0, 1.0),
                &device,
            );
            let hist = Tensor::<5>::zeros([b * n, c, 4, 12, 12], &device);
            let act = Tensor::<3>::zeros([b * n, 4, 2], &device);
            let out = unet.forward(noise, hist, act, None); // [b n, c, 4, 12, 12]
            // One field per (context, future frame): [b 4, n, c 12 12].
            let out = out.reshape([b, n, c, 4, 144]).permute([0, 3, 1, 2, 4]).reshape([b * 4, n, c * 144]);
            let pos = Tensor::<3>::zeros([b * 4, 1, c * 144], &device);
            let (loss, _) = drift_loss(out, None, &pos, &PUSHT_TEMPERATURES);
            let grads = GradientsParams::from_grads(loss.backward(), &unet);
            unet = optim.step(1e-4, unet, grads);
            eprintln!("step {i}: {:.2} s ({} params)", t0.elapsed().as_secs_f64(), unet.num_params());
        }
    }
}
