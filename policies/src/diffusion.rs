//! The `diffusion` policy kind: DDPM training with ε-prediction on a squared-cosine
//! schedule (diffusers' `squaredcos_cap_v2`), few-step deterministic DDIM at
//! inference with x₀ clipped to [-1, 1], positions min-max normalised to [-1, 1].
//!
//! An observation is the last `obs_horizon` frames and agent positions; the
//! policy predicts `horizon` actions and executes `action_horizon` of them from
//! index `obs_horizon − 1` (the step of the current observation), as in Chi et al.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use harness::policy::{ActionChunk, Observation, Policy, PolicyError, sanitize};
use harness::rng::Rng;
use serde::{Deserialize, Serialize};

use crate::cpu_encoder::CpuEncoder;
use crate::cpu_unet::{CpuUnet1d, Products};
use crate::net::{CondUnet1d, NetConfig, ObsEncoder};

/// Per-entry min-max statistics of a vector quantity.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Range {
    /// Per-entry minimum.
    pub min: Vec<f32>,
    /// Per-entry maximum.
    pub max: Vec<f32>,
}

impl Range {
    /// Entries per vector.
    pub fn dim(&self) -> usize {
        self.min.len()
    }

    /// To [-1, 1], entry by entry (`v` has [`Range::dim`] entries).
    pub fn normalise<'a>(&'a self, v: &'a [f32]) -> impl Iterator<Item = f32> + 'a {
        v.iter()
            .zip(self.min.iter().zip(&self.max))
            .map(|(x, (lo, hi))| 2.0 * (x - lo) / (hi - lo).max(1e-6) - 1.0)
    }

    /// From [-1, 1], entry by entry.
    pub fn denormalise(&self, v: &[f32]) -> Vec<f32> {
        v.iter()
            .zip(self.min.iter().zip(&self.max))
            .map(|(x, (lo, hi))| (x + 1.0) / 2.0 * (hi - lo) + lo)
            .collect()
    }
}

/// Normalisation statistics (from the training data).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Normalisation {
    /// The proprioceptive vector (Push-T: the agent's position; the name is the
    /// one `policy.json` files carry).
    pub agent_pos: Range,
    /// Actions.
    pub action: Range,
}

/// The `diffusion` kind's configuration (`policy.json` "config").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiffusionConfig {
    /// Networks.
    pub net: NetConfig,
    /// Predicted actions per decision.
    pub horizon: usize,
    /// Executed actions per decision.
    pub action_horizon: usize,
    /// DDPM training steps T.
    pub train_steps: usize,
    /// DDIM steps at inference.
    pub inference_steps: usize,
}

impl DiffusionConfig {
    /// The most actions a decision can execute: the predicted window starts at the
    /// oldest observed step, so `horizon - obs_horizon + 1` of them lie ahead.
    pub fn max_action_horizon(&self) -> usize {
        (self.horizon + 1).saturating_sub(self.net.obs_horizon)
    }
}

impl Default for DiffusionConfig {
    fn default() -> Self {
        Self { net: NetConfig::new(), horizon: 16, action_horizon: 8, train_steps: 100, inference_steps: 10 }
    }
}

/// ᾱ_t of diffusers' `squaredcos_cap_v2` schedule: β_i = min(1 − ᾱ(i+1)/ᾱ(i), 0.999)
/// with ᾱ(t) = cos²((t/T + 0.008)/1.008 · π/2).
pub fn alphas_cumprod(steps: usize) -> Vec<f64> {
    let f =
        |i: usize| ((i as f64 / steps as f64 + 0.008) / 1.008 * std::f64::consts::FRAC_PI_2).cos().powi(2);
    let mut acc = 1.0;
    (0..steps)
        .map(|i| {
            let beta = (1.0 - f(i + 1) / f(i)).min(0.999);
            acc *= 1.0 - beta;
            acc
        })
        .collect()
}

/// The networks of a diffusion policy.
#[derive(Module, Debug)]
pub struct DiffusionNet {
    /// Frame encoder.
    pub encoder: ObsEncoder,
    /// Noise predictor.
    pub unet: CondUnet1d,
}

impl DiffusionNet {
    /// Builds fresh networks.
    pub fn new(cfg: &DiffusionConfig, device: &Device) -> Self {
        Self { encoder: ObsEncoder::new(&cfg.net, device), unet: CondUnet1d::new(&cfg.net, device) }
    }

    /// Observation conditioning.
    ///
    /// # Shapes
    /// - `frames`: `[b·o, 3, 96, 96]` in [-1, 1] (episode-major, oldest first)
    /// - `pos`: `[b, o, p]` normalised proprioception
    /// - returns `[b, o·(feature + p)]`
    pub fn obs_cond(&self, frames: Tensor<4>, pos: Tensor<3>) -> Tensor<2> {
        let [b, o, p] = pos.dims();
        let feat = self.encoder.forward(frames); // [b o, f]
        let f = feat.dims()[1];
        Tensor::cat(vec![feat.reshape([b, o, f]), pos], 2).reshape([b, o * (f + p)])
    }

    /// The ε-prediction loss of noisy actions at integer steps `t`.
    ///
    /// # Shapes
    /// `cond: [b, c]`, `actions, noise: [b, horizon, action_dim]`, `t: [b]`
    pub fn loss(
        &self,
        cond: Tensor<2>,
        actions: Tensor<3>,
        noise: Tensor<3>,
        t: &[usize],
        ac: &[f64],
    ) -> Tensor<1> {
        let b = t.len();
        let device = actions.device();
        let coef = |g: &dyn Fn(f64) -> f64| {
            let v: Vec<f32> = t.iter().map(|&i| g(ac[i]) as f32).collect();
            Tensor::<1>::from_floats(v.as_slice(), &device).reshape([b, 1, 1])
        };
        let noisy = actions * coef(&|a| a.sqrt()) + noise.clone() * coef(&|a| (1.0 - a).sqrt());
        let tt: Vec<f32> = t.iter().map(|&i| i as f32).collect();
        let pred = self.unet.forward(noisy, Tensor::from_floats(tt.as_slice(), &device), cond);
        (pred - noise).powf_scalar(2.0).mean()
    }

    /// Deterministic DDIM from noise `x` (`[b, horizon, action_dim]`) with `k` steps.
    pub fn sample(&self, cond: Tensor<2>, mut x: Tensor<3>, k: usize, ac: &[f64]) -> Tensor<3> {
        let b = x.dims()[0];
        let device = x.device();
        for (t, a, a_prev) in ddim_steps(k, ac) {
            let tt = Tensor::<1>::from_floats(vec![t as f32; b].as_slice(), &device);
            let eps = self.unet.forward(x.clone(), tt, cond.clone());
            let x0 = ((x - eps.clone() * (1.0 - a).sqrt()) / a.sqrt()).clamp(-1.0, 1.0);
            x = x0 * a_prev.sqrt() + eps * (1.0 - a_prev).sqrt();
        }
        x
    }
}

/// The `k` DDIM steps over a `T = ac.len()` schedule, noisiest first: `(t, ᾱ_t, ᾱ_prev)`
/// with t = j·⌊T/k⌋ and ᾱ_prev = ᾱ_{t − ⌊T/k⌋} (1 past the last).
pub fn ddim_steps(k: usize, ac: &[f64]) -> Vec<(usize, f64, f64)> {
    let t_total = ac.len();
    let ratio = (t_total / k.max(1)).max(1);
    (0..k.max(1))
        .map(|j| j * ratio)
        .filter(|&t| t < t_total)
        .rev()
        .map(|t| (t, ac[t], if t >= ratio { ac[t - ratio] } else { 1.0 }))
        .collect()
}

/// [`DiffusionNet::sample`] on [`CpuUnet1d`]: `x` is `[b, horizon, action_dim]`, `cond` `[b, c]`.
fn sample_cpu(
    unet: &CpuUnet1d,
    cond: &[f32],
    mut x: Vec<f32>,
    [horizon, action_dim]: [usize; 2],
    k: usize,
    ac: &[f64],
) -> Vec<f32> {
    let prep = unet.prepare(cond, x.len() / (action_dim * horizon).max(1));
    for (t, a, a_prev) in ddim_steps(k, ac) {
        let eps = unet.forward(&prep, &x, horizon, t as f32);
        ddim_update(&mut x, &eps, a, a_prev);
    }
    x
}

/// One deterministic DDIM step (η = 0) of `x` given its predicted noise `eps`, from ᾱ = `a`
/// to ᾱ = `a_prev`: x₀ = (x − √(1 − a) ε) / √a clipped to [-1, 1], then
/// x ← √a_prev x₀ + √(1 − a_prev) ε (the noise kept, not re-derived from the clipped x₀).
pub(crate) fn ddim_update(x: &mut [f32], eps: &[f32], a: f64, a_prev: f64) {
    let (sa, s1a) = (a.sqrt() as f32, (1.0 - a).sqrt() as f32);
    let (sp, s1p) = (a_prev.sqrt() as f32, (1.0 - a_prev).sqrt() as f32);
    for (v, e) in x.iter_mut().zip(eps) {
        let x0 = ((*v - e * s1a) / sa).clamp(-1.0, 1.0);
        *v = x0 * sp + e * s1p;
    }
}

/// The frames and normalised proprioception of a batch of observations, checked: each has
/// `o` frames of `s`² RGB and `o` proprioceptive vectors of `p` entries. Frames are
/// episode-major, oldest first; positions `[b, o, p]` flat.
///
/// # Errors
/// [`PolicyError::Input`] naming the policy and the episode that does not fit.
pub(crate) fn gather<'a>(
    policy: &str,
    obs: &'a [Observation],
    o: usize,
    s: usize,
    p: usize,
    norm: &Normalisation,
) -> Result<(Vec<&'a [u8]>, Vec<f32>), PolicyError> {
    let bad = |m: String| PolicyError::Input { policy: policy.to_string(), message: m };
    let mut frames = Vec::with_capacity(obs.len() * o);
    let mut pos = Vec::with_capacity(obs.len() * o * p);
    for (i, ob) in obs.iter().enumerate() {
        if ob.frames.len() != o || ob.proprio.len() != o {
            return Err(bad(format!("episode {i}: {} frames, the policy takes {o}", ob.frames.len())));
        }
        if ob.size != s || ob.frames.iter().any(|f| f.len() != s * s * 3) {
            return Err(bad(format!("episode {i}: frames are {0}x{0}, the policy takes {s}x{s}", ob.size)));
        }
        if let Some(v) = ob.proprio.iter().find(|v| v.len() != p) {
            return Err(bad(format!(
                "episode {i}: a proprioceptive vector of {} entries, the policy reads {p}",
                v.len()
            )));
        }
        frames.extend(ob.frames.iter().map(Vec::as_slice));
        pos.extend(ob.proprio.iter().flat_map(|v| norm.agent_pos.normalise(v)));
    }
    Ok((frames, pos))
}

/// The executed actions of sampled sequences `v` (`[b, h, ad]` flat, normalised): steps
/// `start .. start + n` of each (as many as the horizon holds), denormalised and clamped into
/// the task's `bounds` (a warning says how many were clamped).
///
/// # Errors
/// [`PolicyError`] from [`sanitize`] (a non-finite action).
pub(crate) fn executed(
    policy: &str,
    v: &[f32],
    [b, h, ad]: [usize; 3],
    start: usize,
    n: usize,
    norm: &Normalisation,
    bounds: &(Vec<f32>, Vec<f32>),
) -> Result<Vec<ActionChunk>, PolicyError> {
    let mut chunks: Vec<ActionChunk> = (0..b)
        .map(|i| {
            (start..(start + n).min(h))
                .map(|t| norm.action.denormalise(&v[(i * h + t) * ad..(i * h + t + 1) * ad]))
                .collect()
        })
        .collect();
    let clamped = sanitize(policy, &mut chunks, &bounds.0, &bounds.1)?;
    if clamped > 0 {
        tracing::warn!(policy = %policy, clamped, "actions outside the task's bounds clamped");
    }
    Ok(chunks)
}

/// A loaded diffusion policy (inference).
pub struct DiffusionPolicy {
    /// Checkpoint name.
    pub name: String,
    /// Configuration.
    pub cfg: DiffusionConfig,
    /// Normalisation.
    pub norm: Normalisation,
    /// Each action entry's bounds in the task: outputs are clamped into them.
    pub bounds: (Vec<f32>, Vec<f32>),
    net: DiffusionNet,
    /// The U-Net on plain CPU loops (Flex device, unless [`POLICY_KERNELS_ENV`] says `burn`).
    cpu_unet: Option<CpuUnet1d>,
    /// The frame encoder on direct CPU kernels (same condition).
    cpu_encoder: Option<CpuEncoder>,
    ac: Vec<f64>,
    device: Device,
}

/// Set to `burn` to sample with burn's U-Net on the CPU too (the direct loops are the default).
pub const POLICY_KERNELS_ENV: &str = "EVALHARNESS_POLICY_KERNELS";

/// Whether networks on `device` run on the project's CPU kernels: on the Flex device, unless
/// [`POLICY_KERNELS_ENV`] says `burn`.
pub fn cpu_kernels_on(device: &Device) -> bool {
    *device == Device::flex() && !std::env::var(POLICY_KERNELS_ENV).is_ok_and(|v| v.trim() == "burn")
}

impl DiffusionPolicy {
    /// Wraps trained networks; `bounds` are the task's action bounds (low, high).
    pub fn new(
        name: String,
        cfg: DiffusionConfig,
        norm: Normalisation,
        bounds: (Vec<f32>, Vec<f32>),
        net: DiffusionNet,
        device: &Device,
    ) -> Self {
        let ac = alphas_cumprod(cfg.train_steps);
        let direct = cpu_kernels_on(device);
        let cpu_unet = direct
            .then(|| {
                CpuUnet1d::new(&net.unet, Products::or_env(Products::GemmCrate))
                    .inspect_err(|e| tracing::warn!(policy = %name, "burn's U-Net kept: {e}"))
            })
            .and_then(Result::ok);
        let cpu_encoder = direct
            .then(|| {
                CpuEncoder::new(&net.encoder)
                    .inspect_err(|e| tracing::warn!(policy = %name, "burn's encoder kept: {e}"))
            })
            .and_then(Result::ok);
        Self { name, cfg, norm, bounds, net, cpu_unet, cpu_encoder, ac, device: device.clone() }
    }
}

pub use nn::frames::{frames_to_tensor, frames_to_vec};

impl Policy for DiffusionPolicy {
    fn name(&self) -> &str {
        &self.name
    }

    fn obs_horizon(&self) -> usize {
        self.cfg.net.obs_horizon
    }

    fn action_horizon(&self) -> usize {
        self.cfg.action_horizon
    }

    fn act(&self, obs: &[Observation], rngs: &mut [Rng]) -> Result<Vec<ActionChunk>, PolicyError> {
        let (o, s, h) = (self.cfg.net.obs_horizon, self.cfg.net.image_size, self.cfg.horizon);
        let (p, ad) = (self.norm.agent_pos.dim(), self.norm.action.dim());
        let bad = |m: String| PolicyError::Input { policy: self.name.clone(), message: m };
        let (frames, pos) = gather(&self.name, obs, o, s, p, &self.norm)?;
        let b = obs.len();
        // Conditioning [b, o·(features + p)]: per observed frame, its features and proprioception.
        let cond: Vec<f32> = match &self.cpu_encoder {
            Some(enc) => {
                let feat = enc.forward(&frames_to_vec(&frames, s), b * o, s); // [b o, f]
                let f = feat.len() / (b * o).max(1);
                feat.chunks(f).zip(pos.chunks(p)).flat_map(|(x, q)| x.iter().chain(q)).copied().collect()
            }
            None => self
                .net
                .obs_cond(
                    frames_to_tensor(&frames, s, &self.device),
                    Tensor::from_data(TensorData::new(pos, [b, o, p]), &self.device),
                )
                .into_data()
                .convert::<f32>()
                .try_into_vec::<f32>()
                .unwrap_or_default(),
        };
        let noise: Vec<f32> = rngs.iter_mut().flat_map(|r| r.normals_f32(h * ad)).collect();
        let v: Vec<f32> = match &self.cpu_unet {
            Some(unet) => sample_cpu(unet, &cond, noise, [h, ad], self.cfg.inference_steps, &self.ac),
            None => {
                let c = cond.len() / b.max(1);
                let cond = Tensor::from_data(TensorData::new(cond, [b, c]), &self.device);
                let x = Tensor::from_data(TensorData::new(noise, [b, h, ad]), &self.device);
                let out = self.net.sample(cond, x, self.cfg.inference_steps, &self.ac);
                out.into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
            }
        };
        if v.len() != b * h * ad {
            return Err(bad(format!("the network returned {} values, expected {}", v.len(), b * h * ad)));
        }
        executed(&self.name, &v, [b, h, ad], o - 1, self.cfg.action_horizon, &self.norm, &self.bounds)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn squared_cosine_schedule() {
        let ac = alphas_cumprod(100);
        // β_0 = 1 − f(1)/f(0), f(i) = cos²((i/100 + 0.008)/1.008 · π/2):
        // f(0) = cos²(0.012467) = 0.999845, f(1) = cos²(0.028050) = 0.999213, β_0 = 6.313e-4.
        assert!((1.0 - ac[0] - 6.313e-4).abs() < 1e-6, "{}", 1.0 - ac[0]);
        assert!(ac.windows(2).all(|w| w[1] < w[0]));
        // The product of (1 − β_i) ends at 2.43e-7 (the last β is capped at 0.999).
        assert!((ac[99] / 2.4286e-7 - 1.0).abs() < 1e-3, "{}", ac[99]);
    }

    #[test]
    fn normalisation_round_trips() {
        let r = Range { min: vec![10.0, 0.0, -1.0], max: vec![500.0, 512.0, 1.0] };
        // 2(10 − 10)/490 − 1 = −1; 2(512 − 0)/512 − 1 = 1; 2(0 + 1)/2 − 1 = 0.
        assert_eq!(r.normalise(&[10.0, 512.0, 0.0]).collect::<Vec<_>>(), vec![-1.0, 1.0, 0.0]);
        let back = r.denormalise(&r.normalise(&[123.0, 45.0, 0.25]).collect::<Vec<_>>());
        assert!((back[0] - 123.0).abs() < 1e-4 && (back[1] - 45.0).abs() < 1e-4, "{back:?}");
        assert!((back[2] - 0.25).abs() < 1e-6, "{back:?}");
    }
}
