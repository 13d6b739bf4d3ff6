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
//! With `anchor` (not in the paper either) the episode's first observed frame is
//! fed too, broadcast over F like the history: in a closed-loop rollout the
//! history soon holds only the model's own output, while the anchor stays a real
//! frame showing the static scene (Push-T's goal T, which never moves) and the
//! block's true shape, so the network can copy what does not change instead of
//! re-deriving it from its own drifting predictions.
//! Skips follow the ADM layout: one after `conv_in`, one after every residual
//! block (with its attention) and one after every downsampling.

pub mod accent;
pub mod blocks;
mod config;
pub mod cpu;
#[cfg(test)]
mod cpu_tests;
mod maps;

pub use config::UNetConfig;
pub use maps::{ACTION_MAP_SIGMA, action_maps};

use burn::module::Module;
use burn::nn::interpolate::{Interpolate2d, Interpolate2dConfig, InterpolateMode};
use burn::nn::{GroupNorm, GroupNormConfig, Initializer, Linear, LinearConfig};
use burn::tensor::activation::silu;
use burn::tensor::{Device, Tensor};

use accent::AlphaMlp;
use blocks::{Attention, Conv3dF, ResBlock, group_norm};

impl UNetConfig {
    /// Builds the module.
    pub fn init(&self, device: &Device) -> UNet {
        let (e, g) = (self.emb_dim, self.groups);
        let mc = self.model_channels;
        let in_ch = self.frame_channels * (1 + self.history + usize::from(self.uses_anchor()))
            + usize::from(self.uses_action_maps());
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
            alpha: self.uses_accentuation().then(|| AlphaMlp::new(e, device)),
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
            frame_channels: self.frame_channels,
            action_maps: self.uses_action_maps(),
            anchor: self.uses_anchor(),
            frame_attention_norm: self.frame_attention_norm(),
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
    fn forward(&self, x: Tensor<5>, emb: Tensor<3>, per_frame: bool) -> Tensor<5> {
        let h = self.res.forward(x, emb);
        match &self.attn {
            Some(a) => a.forward_normed(h, per_frame),
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
    alpha: Option<AlphaMlp>,
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
    frame_channels: usize,
    action_maps: bool,
    anchor: bool,
    frame_attention_norm: bool,
}

impl UNet {
    /// Predicts F future frames in one pass.
    ///
    /// # Shapes
    /// - `noise`: `[b, cf, F, h, w]`
    /// - `history`: `[b, cf, K, h, w]`
    /// - `actions`: `[b, F, a]` (a_{t+f} drives frame t+f+1)
    /// - `anchor`: `[b, cf, h, w]`, the episode's first frame (read only by a U-Net
    ///   configured with `anchor`; when it is `None` there, the last history frame
    ///   stands in)
    /// - `timestep`: `[b]` in [0, 1] (diffusion baseline only)
    /// - returns `[b, cf, F, h, w]`
    pub fn forward(
        &self,
        noise: Tensor<5>,
        history: Tensor<5>,
        actions: Tensor<3>,
        anchor: Option<Tensor<4>>,
        timestep: Option<Tensor<1>>,
    ) -> Tensor<5> {
        self.forward_accentuated(noise, history, actions, anchor, timestep, None)
    }

    /// [`Self::forward`] with an accentuation strength `alpha` (`[b]`; read only by a
    /// U-Net configured with `accentuation`, where `None` means α = 1).
    pub fn forward_accentuated(
        &self,
        noise: Tensor<5>,
        history: Tensor<5>,
        actions: Tensor<3>,
        anchor: Option<Tensor<4>>,
        timestep: Option<Tensor<1>>,
        alpha: Option<Tensor<1>>,
    ) -> Tensor<5> {
        let emb = self.embedding(actions.clone(), timestep, alpha); // [b, F, e]
        let x = self.inputs(noise, history, actions, anchor); // [b, c_in, F, h, w]
        let per_frame = self.frame_attention_norm;
        let mut hcur = self.conv_in.forward(x); // [b, mc, F, h, w]
        let mut skips = vec![hcur.clone()];
        let levels = self.downs.len() + 1;
        for l in 0..levels {
            for i in 0..self.res_blocks {
                hcur = self.enc[l * self.res_blocks + i].forward(hcur, emb.clone(), per_frame);
                skips.push(hcur.clone());
            }
            if l + 1 < levels {
                hcur = self.downs[l].forward(hcur); // spatial / 2
                skips.push(hcur.clone());
            }
        }
        hcur = self.mid[0].forward(hcur, emb.clone());
        hcur = self.mid_attn.forward_normed(hcur, per_frame);
        hcur = self.mid[1].forward(hcur, emb.clone());
        let per = self.res_blocks + 1;
        for (k, _) in (0..levels).rev().enumerate() {
            for i in 0..per {
                let skip = skips.pop().unwrap_or_else(|| hcur.clone());
                hcur =
                    self.dec[k * per + i].forward(Tensor::cat(vec![hcur, skip], 1), emb.clone(), per_frame);
            }
            if k + 1 < levels {
                hcur = self.ups[k].forward(self.up2(hcur)); // spatial x 2
            }
        }
        self.conv_out.forward(silu(group_norm(&self.norm_out, hcur)))
    }

    /// The network's input: noise, the history (flattened k-major into channels and
    /// broadcast over F), the action maps and the anchor, concatenated channel-wise.
    ///
    /// # Shapes
    /// As [`Self::forward`]; returns `[b, cf (1 + K) (+ 1) (+ cf), F, h, w]`.
    pub fn inputs(
        &self,
        noise: Tensor<5>,
        history: Tensor<5>,
        actions: Tensor<3>,
        anchor: Option<Tensor<4>>,
    ) -> Tensor<5> {
        let [b, cf, f, h, w] = noise.dims();
        let [_, _, k, _, _] = history.dims();
        let anchor = self.anchor.then(|| {
            let a = anchor.unwrap_or_else(|| history.clone().narrow(2, k - 1, 1).reshape([b, cf, h, w]));
            a.reshape([b, cf, 1, h, w]).expand([b, cf, f, h, w]) // [b, cf, F, h, w]
        });
        let hist = history.swap_dims(1, 2).reshape([b, k * cf, 1, h, w]).expand([b, k * cf, f, h, w]); // k-major
        let mut parts = vec![noise, hist]; // [b, cf, F, h, w], [b, cf K, F, h, w]
        if self.action_maps {
            parts.push(action_maps(actions, h, w)); // [b, 1, F, h, w]
        }
        parts.extend(anchor);
        Tensor::cat(parts, 1)
    }

    /// The per-frame conditioning: the action MLP, plus the timestep MLP's output
    /// (diffusion baseline, when `timestep` is given), plus the α MLP's (accentuation;
    /// α = 1 when `alpha` is `None`).
    ///
    /// # Shapes
    /// `actions` `[b, F, a]`, `timestep` and `alpha` `[b]` → `[b, F, e]`
    pub fn embedding(
        &self,
        actions: Tensor<3>,
        timestep: Option<Tensor<1>>,
        alpha: Option<Tensor<1>>,
    ) -> Tensor<3> {
        let [b, _, _] = actions.dims();
        let device = actions.device();
        let mut emb = self.act2.forward(silu(self.act1.forward(actions))); // [b, F, e]
        if let (Some(mlp), Some(t)) = (&self.time, timestep) {
            let te = mlp.l2.forward(silu(mlp.l1.forward(sinusoidal(t, self.emb_dim)))); // [b, e]
            emb = emb + te.unsqueeze_dim::<3>(1);
        }
        if let Some(mlp) = &self.alpha {
            let alpha = alpha.unwrap_or_else(|| Tensor::ones([b], &device));
            emb = emb + mlp.forward(alpha).unsqueeze_dim::<3>(1); // [b, 1, e] over F
        }
        emb
    }

    /// The same network with an action-map input channel added, its weights
    /// zero: it computes exactly what it did before, and training can then learn
    /// to use the maps (warm-starting an `action_maps` run from one without).
    pub fn with_action_maps(mut self) -> Self {
        if !self.action_maps {
            // The map channel comes before the anchor's (see `forward`).
            let after = if self.anchor { self.frame_channels } else { 0 };
            self.conv_in = self.conv_in.with_extra_inputs(1, after);
            self.action_maps = true;
        }
        self
    }

    /// The same network with anchor input channels added (after the action map, if
    /// any), their weights zero: it computes exactly what it did before, and training
    /// can then learn to use the anchor (warm-starting an `anchor` run from one without).
    pub fn with_anchor(mut self) -> Self {
        if !self.anchor {
            self.conv_in = self.conv_in.with_extra_inputs(self.frame_channels, 0);
            self.anchor = true;
        }
        self
    }

    /// The same network with a timestep embedding added whose output layer is
    /// zero: it computes exactly what it did before at every t, and training can
    /// then learn to use t (warm-starting the diffusion baseline from a one-pass
    /// model).
    pub fn with_timestep_embedding(mut self, device: &Device) -> Self {
        if self.time.is_none() {
            let e = self.emb_dim;
            let zero = LinearConfig::new(e, e).with_initializer(Initializer::Zeros).init(device);
            self.time = Some(TimeMlp { l1: LinearConfig::new(e, e).init(device), l2: zero });
        }
        self
    }

    /// The same network reading an accentuation strength α through a new α MLP whose
    /// output layer is zero: it computes exactly what it did before at every α, and
    /// training can then learn to use α (warm-starting an accentuated run).
    pub fn with_accentuation(mut self, device: &Device) -> Self {
        if self.alpha.is_none() {
            self.alpha = Some(AlphaMlp::new(self.emb_dim, device));
        }
        self
    }

    /// Nearest-neighbour 2x upsampling in space.
    fn up2(&self, x: Tensor<5>) -> Tensor<5> {
        let [b, c, f, h, w] = x.dims();
        self.upsample.forward(x.reshape([b, c * f, h, w])).reshape([b, c, f, 2 * h, 2 * w])
    }
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
mod tests;
