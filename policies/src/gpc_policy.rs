//! The `gpc-diffusion` policy kind: DriftWorld/GPC's Push-T diffusion policies (Chi et al.'s
//! diffusion policy as GPC trains it), imported from their PyTorch checkpoints
//! ([`crate::import_gpc`]).
//!
//! - Each of the last `obs_horizon` frames, in [0, 1], goes through a ResNet-18 with GroupNorm
//!   ([`ResNet18Gn`], 512 features); the conditioning is, per frame, its features then the
//!   agent position min-max normalised to [-1, 1] (oldest frame first).
//! - [`CondUnet1d`] (diffusion_policy's `ConditionalUnet1D`, 1:1) predicts the noise of the
//!   `horizon`-step action sequence.
//! - Sampling is DDPM over every training step (diffusers' `DDPMScheduler`: squared-cosine
//!   betas, ε-prediction, x₀ clipped to [-1, 1], "fixed small" variance), stochastic: the
//!   initial noise and each step's noise come from the episode's own generator, so a run is
//!   reproducible and independent of batching, not equal to PyTorch's draws.
//! - Actions `obs_horizon − 1 ..` `+ action_horizon` of the sequence are executed.

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use harness::policy::{ActionChunk, Observation, Policy, PolicyError, sanitize};
use harness::rng::Rng;
use serde::{Deserialize, Serialize};

use crate::cpu_unet::CpuUnet1d;
use crate::diffusion::{Normalisation, alphas_cumprod};
use crate::net::{CondUnet1d, NetConfig};
use crate::resnet_gn::ResNet18Gn;

/// The `gpc-diffusion` kind's configuration (`policy.json` "config").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GpcConfig {
    /// The ResNet's base width (64 in GPC's policies: 512 features).
    pub resnet_base: usize,
    /// The U-Net's sizes (`feature_dim` = 8 × `resnet_base`; `encoder_width` unused).
    pub net: NetConfig,
    /// Predicted actions per decision.
    pub horizon: usize,
    /// Executed actions per decision.
    pub action_horizon: usize,
    /// DDPM steps (training and sampling).
    pub train_steps: usize,
}

impl GpcConfig {
    /// The most actions a decision can execute (from the current observation's step on).
    pub fn max_action_horizon(&self) -> usize {
        (self.horizon + 1).saturating_sub(self.net.obs_horizon)
    }
}

/// The networks of a GPC policy.
#[derive(Module, Debug)]
pub struct GpcNet {
    /// Frame encoder.
    pub encoder: ResNet18Gn,
    /// Noise predictor.
    pub unet: CondUnet1d,
}

impl GpcNet {
    /// Fresh networks of `cfg`'s sizes.
    pub fn new(cfg: &GpcConfig, device: &Device) -> Self {
        Self { encoder: ResNet18Gn::new(cfg.resnet_base, device), unet: CondUnet1d::new(&cfg.net, device) }
    }

    /// Observation conditioning.
    ///
    /// # Shapes
    /// - `frames`: `[b·o, 3, h, w]` in [0, 1] (episode-major, oldest first)
    /// - `pos`: `[b, o, p]` normalised proprioception
    /// - returns `[b, o·(features + p)]`
    pub fn obs_cond(&self, frames: Tensor<4>, pos: Tensor<3>) -> Tensor<2> {
        let [b, o, p] = pos.dims();
        let feat = self.encoder.forward(frames); // [b o, f]
        let f = feat.dims()[1];
        Tensor::cat(vec![feat.reshape([b, o, f]), pos], 2).reshape([b, o * (f + p)])
    }
}

/// One DDPM step from `x` at step `t` given the predicted noise `eps`: the posterior mean of
/// x₀ clipped to [-1, 1], plus `√variance · z` for `t > 0` (`z` standard normal).
/// `ac` is ᾱ over the schedule.
pub fn ddpm_step(x: &mut [f32], eps: &[f32], t: usize, ac: &[f64], z: &[f32]) {
    let (a, ap) = (ac[t], if t > 0 { ac[t - 1] } else { 1.0 });
    let cur = a / ap;
    let (sa, s1a) = (a.sqrt(), (1.0 - a).sqrt());
    let c0 = (ap.sqrt() * (1.0 - cur) / (1.0 - a)) as f32;
    let ct = (cur.sqrt() * (1.0 - ap) / (1.0 - a)) as f32;
    let sd = if t > 0 { ((1.0 - ap) / (1.0 - a) * (1.0 - cur)).max(1e-20).sqrt() as f32 } else { 0.0 };
    for (i, (v, e)) in x.iter_mut().zip(eps).enumerate() {
        let x0 = ((f64::from(*v) - s1a * f64::from(*e)) / sa).clamp(-1.0, 1.0) as f32;
        *v = c0 * x0 + ct * *v + if t > 0 { sd * z[i] } else { 0.0 };
    }
}

/// DDPM sampling of `x` (`[b, horizon, action_dim]`, flat) over every step of `ac`, with the
/// noise predictor `eps(x, t)` and step noise from `noise(len)`.
pub fn ddpm_sample(
    mut x: Vec<f32>,
    ac: &[f64],
    mut eps: impl FnMut(&[f32], usize) -> Vec<f32>,
    mut noise: impl FnMut(usize) -> Vec<f32>,
) -> Vec<f32> {
    for t in (0..ac.len()).rev() {
        let e = eps(&x, t);
        let z = if t > 0 { noise(x.len()) } else { Vec::new() };
        ddpm_step(&mut x, &e, t, ac, &z);
    }
    x
}

/// A loaded GPC policy (inference).
pub struct GpcPolicy {
    /// Checkpoint name.
    pub name: String,
    /// Configuration.
    pub cfg: GpcConfig,
    /// Normalisation (GPC's evaluation script's statistics, recorded at import).
    pub norm: Normalisation,
    /// Each action entry's bounds in the task: outputs are clamped into them.
    pub bounds: (Vec<f32>, Vec<f32>),
    net: GpcNet,
    /// The U-Net on plain CPU loops (on the CPU device).
    cpu_unet: Option<CpuUnet1d>,
    ac: Vec<f64>,
    device: Device,
}

impl GpcPolicy {
    /// Wraps imported networks; `bounds` are the task's action bounds (low, high).
    pub fn new(
        name: String,
        cfg: GpcConfig,
        norm: Normalisation,
        bounds: (Vec<f32>, Vec<f32>),
        net: GpcNet,
        device: &Device,
    ) -> Self {
        let ac = alphas_cumprod(cfg.train_steps);
        let cpu_unet = (*device == Device::flex())
            .then(|| {
                CpuUnet1d::new(&net.unet)
                    .inspect_err(|e| tracing::warn!(policy = %name, "burn's U-Net kept: {e}"))
            })
            .and_then(Result::ok);
        Self { name, cfg, norm, bounds, net, cpu_unet, ac, device: device.clone() }
    }

    /// The noise prediction for `x` (`[b, horizon, action_dim]`) at step `t` under `cond`.
    fn eps(&self, cond: &[f32], x: &[f32], b: usize, t: usize) -> Vec<f32> {
        let (h, ad) = (self.cfg.horizon, self.cfg.net.action_dim);
        if let Some(unet) = &self.cpu_unet {
            let prep = unet.prepare(cond, b);
            return unet.forward(&prep, x, h, t as f32);
        }
        let c = cond.len() / b.max(1);
        let cond = Tensor::from_data(TensorData::new(cond.to_vec(), [b, c]), &self.device);
        let x = Tensor::from_data(TensorData::new(x.to_vec(), [b, h, ad]), &self.device);
        let tt = Tensor::<1>::from_floats(vec![t as f32; b].as_slice(), &self.device);
        self.net
            .unet
            .forward(x, tt, cond)
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap_or_default()
    }
}

impl Policy for GpcPolicy {
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
        let (frames, pos) = crate::diffusion::gather(&self.name, obs, o, s, p, &self.norm)?;
        let bad = |m: String| PolicyError::Input { policy: self.name.clone(), message: m };
        let b = obs.len();
        let x01 = world_model::data::frames_to_tensor(&frames, s, &self.device) * 0.5 + 0.5;
        let pos = Tensor::from_data(TensorData::new(pos, [b, o, p]), &self.device);
        let cond = self
            .net
            .obs_cond(x01, pos)
            .into_data()
            .convert::<f32>()
            .try_into_vec::<f32>()
            .unwrap_or_default();
        // Each episode's initial noise, then each step's, from its own generator.
        let x: Vec<f32> = rngs.iter_mut().flat_map(|r| r.normals_f32(h * ad)).collect();
        let per = h * ad;
        let v = ddpm_sample(
            x,
            &self.ac,
            |x, t| self.eps(&cond, x, b, t),
            |_| rngs.iter_mut().flat_map(|r| r.normals_f32(per)).collect(),
        );
        if v.len() != b * h * ad || v.iter().any(|x| !x.is_finite()) {
            return Err(bad(format!(
                "the network returned {} values (finite?), expected {}",
                v.len(),
                b * h * ad
            )));
        }
        let start = o - 1;
        let mut chunks: Vec<ActionChunk> = (0..b)
            .map(|i| {
                (start..(start + self.cfg.action_horizon).min(h))
                    .map(|t| self.norm.action.denormalise(&v[(i * h + t) * ad..(i * h + t + 1) * ad]))
                    .collect()
            })
            .collect();
        let clamped = sanitize(&self.name, &mut chunks, &self.bounds.0, &self.bounds.1)?;
        if clamped > 0 {
            tracing::warn!(policy = %self.name, clamped, "actions outside the task's bounds clamped");
        }
        Ok(chunks)
    }
}

/// Loads a `gpc-diffusion` checkpoint folder (`policy.json` + `model.bpk`), checked against
/// what the scenario gives.
///
/// # Errors
/// [`PolicyLoadError`] naming the folder for a config that does not fit the scenario or
/// weights that are missing, truncated or do not match it.
pub fn load(
    dir: &std::path::Path,
    file: crate::dir::PolicyFile,
    expect: &crate::dir::Expectations,
    device: &Device,
) -> Result<Box<dyn Policy>, crate::dir::PolicyLoadError> {
    let err = |m: String| crate::dir::PolicyLoadError::new(dir, m);
    let cfg: GpcConfig = serde_json::from_value(file.config.clone())
        .map_err(|e| err(format!("policy.json \"config\": {e}")))?;
    let n = &cfg.net;
    if n.image_size != expect.image_size {
        return Err(err(format!(
            "takes {0}x{0} frames, the scenario renders {1}x{1}",
            n.image_size, expect.image_size
        )));
    }
    if n.action_dim != expect.action_dim() || n.proprio() != expect.proprio_dim {
        return Err(err(format!(
            "acts in {}-D and reads {} proprioceptive entries, the scenario takes {}-D and gives {}",
            n.action_dim,
            n.proprio(),
            expect.action_dim(),
            expect.proprio_dim
        )));
    }
    let norm = &file.normalisation;
    if norm.agent_pos.dim() != n.proprio() || norm.action.dim() != n.action_dim {
        return Err(err("policy.json \"normalisation\" does not fit the config".into()));
    }
    if cfg.action_horizon == 0 || cfg.action_horizon > cfg.max_action_horizon() || cfg.train_steps == 0 {
        return Err(err(format!(
            "action horizon {} does not fit horizon {}",
            cfg.action_horizon, cfg.horizon
        )));
    }
    let net = crate::dir::load_weights(GpcNet::new(&cfg, device), &dir.join("model.bpk"))
        .map_err(|e| err(format!("model.bpk: {e}")))?;
    let bounds = (expect.action_low.clone(), expect.action_high.clone());
    let name = crate::dir::checkpoint_name(dir);
    Ok(Box::new(GpcPolicy::new(name, cfg, file.normalisation, bounds, net, device)))
}

#[cfg(test)]
#[path = "gpc_policy_tests.rs"]
mod tests;
