//! A trained world model for inference: the frame codec (autoencoder latents or
//! pixels), the (EMA) U-Net and the sampler of its objective, behind one
//! "predict the next F frames" call.
//!
//! - `drifting` and `mse`: one U-Net pass maps noise + history + actions to F frames.
//! - `diffusion`: v- (or x0-) prediction with a cosine schedule, sampled with K
//!   deterministic DDIM steps (K U-Net passes per chunk) — the multi-step baseline.
//!
//! Sampling noise comes from per-row RNGs the caller owns, so a row's frames
//! never depend on the batch it runs in.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Tensor, TensorData};
use harness::rng::Rng;
use serde::{Deserialize, Serialize};

use crate::action::ActionScale;
use crate::codec::FrameCodec;
use crate::cpu_decoder::CpuDecoder;
use crate::error::{SettingError, WorldModelError};
use crate::latents::LatentStats;
use crate::train_ae::ckpt;
use crate::unet::cpu::CpuUNet;
use crate::unet::{UNet, UNetConfig};

/// The training objective, which also decides how frames are sampled.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Objective {
    /// DriftWorld: the drifting loss, one pass per chunk.
    Drifting,
    /// One-step regression baseline, one pass per chunk.
    Mse,
    /// Multi-step diffusion baseline (v- or x0-prediction, DDIM sampling).
    Diffusion,
}

impl Objective {
    /// The lowercase name used on the command line and in files.
    pub fn name(self) -> &'static str {
        match self {
            Objective::Drifting => "drifting",
            Objective::Mse => "mse",
            Objective::Diffusion => "diffusion",
        }
    }
}

/// What the diffusion baseline's U-Net outputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Prediction {
    /// v = √ᾱ·ε − √(1−ᾱ)·x0 (Salimans & Ho).
    #[default]
    V,
    /// The clean frames x0 — what a one-pass model outputs, so a diffusion baseline
    /// can start from a drifting or MSE model's weights.
    X0,
}

/// A world-model folder's `config.json`: the model's configuration, and what else the
/// folder's maker wrote beside it (a trainer's `train`, an import's `import`), kept as
/// written so that `wm export` can rewrite the model's entry without losing the rest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FolderConfig {
    /// The model's configuration.
    pub model: WorldModelConfig,
    /// The other entries, as written.
    #[serde(flatten)]
    pub rest: std::collections::BTreeMap<String, serde_json::Value>,
}

impl FolderConfig {
    /// `dir/config.json`.
    ///
    /// # Errors
    /// [`WorldModelError::Checkpoint`] naming the file when it is missing or malformed.
    pub fn read(dir: &Path) -> Result<Self, WorldModelError> {
        let path = dir.join("config.json");
        harness::runfile::read(&path).map_err(WorldModelError::from)
    }
}

/// Everything needed to rebuild a world model (its `config.json` "model" entry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldModelConfig {
    /// Training objective / sampler.
    pub objective: Objective,
    /// U-Net hyper-parameters.
    pub unet: UNetConfig,
    /// Per-channel normalisation of the encoded frames.
    pub latents: LatentStats,
    /// The autoencoder folder, relative to the world-model folder; `null` for a
    /// pixel-space model (`--config pusht-pixel`).
    pub autoencoder: Option<PathBuf>,
    /// Future frames per pass F.
    pub future: usize,
    /// DDIM steps per chunk (diffusion only).
    pub sample_steps: usize,
    /// The diffusion U-Net's output (absent: v, and for the one-pass objectives).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prediction: Option<Prediction>,
    /// Action-accentuation strength α at inference (spec §3; read only by a U-Net
    /// trained with accentuation; absent: 1, no accentuation).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<f32>,
    /// Trained on frames without the scenario's static goal (`train world-model
    /// --goal-free`; not in the paper): its users give it goal-free frames and draw
    /// the known goal onto what it generates. Absent: the frames show the goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal_free: Option<bool>,
    /// How actions are normalised (absent: Push-T's world units, [`ActionScale::pusht`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub actions: Option<ActionScale>,
    /// The scale of a one-pass model's input noise at inference: the generator's
    /// temperature, as the truncation trick of GAN sampling (Brock et al. 2019) lowers
    /// it. 0 gives each history and action sequence one fixed chunk; absent: 1, the
    /// standard-normal noise the model was trained on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub noise_scale: Option<f32>,
}

impl WorldModelConfig {
    /// Whether the model works on goal-free frames (see [`WorldModelConfig::goal_free`]).
    pub fn is_goal_free(&self) -> bool {
        self.goal_free == Some(true)
    }

    /// How the model normalises actions ([`WorldModelConfig::actions`]).
    pub fn action_scale(&self) -> ActionScale {
        self.actions.clone().unwrap_or_else(ActionScale::pusht)
    }

    /// A one-pass drifting model on raw 3-channel frames of `size`² (no autoencoder,
    /// unit normalisation): the pixel family's shape, for tests and benchmarks.
    pub fn pixels(unet: UNetConfig, size: usize) -> Self {
        Self {
            objective: Objective::Drifting,
            unet,
            latents: LatentStats { channels: 3, size, mean: vec![0.0; 3], std: vec![1.0; 3] },
            autoencoder: None,
            future: 4,
            sample_steps: 1,
            prediction: None,
            alpha: None,
            goal_free: None,
            actions: None,
            noise_scale: None,
        }
    }

    /// The `"model"` entry of `dir/config.json`.
    ///
    /// # Errors
    /// [`WorldModelError::Checkpoint`] naming the file when it is missing or malformed.
    pub fn read(dir: &Path) -> Result<Self, WorldModelError> {
        let cfg = FolderConfig::read(dir)?.model;
        cfg.unet.check().map_err(|e| ckpt(&dir.join("config.json"), format!("\"model.unet\": {e}")))?;
        Ok(cfg)
    }

    /// The frame codec of a model stored in `dir`: its autoencoder (a path relative
    /// to `dir`) or, without one, pixels of `latents.size`.
    ///
    /// # Errors
    /// [`WorldModelError::Checkpoint`] naming the autoencoder file at fault.
    pub fn codec(&self, dir: &Path, device: &Device) -> Result<FrameCodec, WorldModelError> {
        match &self.autoencoder {
            Some(ae) => FrameCodec::autoencoder(&dir.join(ae), device),
            None => Ok(FrameCodec::pixels(self.latents.size)),
        }
    }
}

/// ᾱ(t) of the cosine schedule (Nichol & Dhariwal), t ∈ [0, 1].
pub fn alpha_bar(t: f64) -> f64 {
    let s = 0.008;
    let f = |t: f64| ((t + s) / (1.0 + s) * std::f64::consts::FRAC_PI_2).cos().powi(2);
    (f(t) / f(0.0)).clamp(1e-5, 1.0)
}

/// A loaded world model (inference only, EMA weights).
pub struct WorldModel {
    /// Its configuration.
    pub cfg: WorldModelConfig,
    codec: FrameCodec,
    unet: UNet,
    device: Device,
    /// The decoder on direct CPU kernels (Flex device and latent family only).
    cpu_decoder: Option<CpuDecoder>,
    /// The U-Net on CPU kernels (Flex device only).
    cpu_unet: Option<CpuUNet>,
}

/// Set to `burn` to decode with burn's convolutions even on the CPU (for comparisons).
pub const DECODER_ENV: &str = "EVALHARNESS_DECODER";

/// The direct-kernel decoder for a latent codec on the Flex device, unless
/// [`DECODER_ENV`] asks for burn's; `None` elsewhere (GPU, pixels, unsupported layers).
fn cpu_decoder(codec: &FrameCodec, device: &Device) -> Option<CpuDecoder> {
    let FrameCodec::Latent { ae, .. } = codec else { return None };
    if *device != Device::flex() || std::env::var(DECODER_ENV).is_ok_and(|v| v.trim() == "burn") {
        return None;
    }
    CpuDecoder::new(ae, codec.size())
        .inspect_err(|e| tracing::warn!("decoding with burn's convolutions: {e}"))
        .ok()
}

/// Set to `burn` to run the U-Net with burn's operations even on the CPU (for comparisons).
pub const UNET_ENV: &str = "EVALHARNESS_UNET";

/// The U-Net on CPU kernels on the Flex device, unless [`UNET_ENV`] asks for burn's.
fn cpu_unet(unet: &UNet, device: &Device) -> Option<CpuUNet> {
    if *device != Device::flex() || std::env::var(UNET_ENV).is_ok_and(|v| v.trim() == "burn") {
        return None;
    }
    CpuUNet::new(unet).inspect_err(|e| tracing::warn!("predicting with burn's U-Net: {e}")).ok()
}

/// Standard-normal noise `[rows, per]`, row r drawn from `rngs[r]`.
pub fn row_noise(rngs: &mut [Rng], per: usize) -> Vec<f32> {
    rngs.iter_mut().flat_map(|r| r.normals_f32(per)).collect()
}

impl WorldModel {
    /// Loads `dir/config.json` and `dir/ema.bpk`, and the autoencoder it names (if any).
    ///
    /// # Errors
    /// [`WorldModelError::Checkpoint`] naming the file that is missing, unreadable or
    /// does not match its config.
    pub fn load(dir: &Path, device: &Device) -> Result<Self, WorldModelError> {
        let cfg_path = dir.join("config.json");
        let cfg = WorldModelConfig::read(dir)?;
        let weights = dir.join("ema.bpk");
        let unet = cfg.unet.init(device).try_load_file(&weights).map_err(|e| ckpt(&weights, e))?;
        let codec = cfg.codec(dir, device)?;
        if codec.channels() != cfg.latents.channels || codec.size() != cfg.latents.size {
            let what = if codec.is_pixels() { "the U-Net's frames" } else { "the autoencoder's latents" };
            return Err(ckpt(&cfg_path, format!("\"latents\" shape differs from {what}")));
        }
        if codec.channels() != cfg.unet.frame_channels {
            return Err(ckpt(&cfg_path, "\"unet.frame_channels\" differs from the encoded frames' channels"));
        }
        let cpu_decoder = cpu_decoder(&codec, device);
        let cpu_unet = cpu_unet(&unet, device);
        let mut wm = Self { cfg, codec, unet, device: device.clone(), cpu_decoder, cpu_unet };
        if let Some(t) = wm.cfg.noise_scale {
            wm.set_noise_scale(t).map_err(|e| ckpt(&cfg_path, format!("\"noise_scale\": {e}")))?;
        }
        Ok(wm)
    }

    /// Builds a model from parts (used by the trainer's evaluation).
    pub fn from_parts(cfg: WorldModelConfig, codec: FrameCodec, unet: UNet, device: &Device) -> Self {
        let cpu_decoder = cpu_decoder(&codec, device);
        let cpu_unet = cpu_unet(&unet, device);
        Self { cfg, codec, unet, device: device.clone(), cpu_decoder, cpu_unet }
    }

    /// The RGB frames' side the model reads and writes.
    pub fn image_size(&self) -> usize {
        self.codec.image_size()
    }

    /// The device it runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// U-Net passes per generated chunk.
    pub fn passes_per_chunk(&self) -> usize {
        if self.cfg.objective == Objective::Diffusion { self.cfg.sample_steps } else { 1 }
    }

    /// Encodes frames in [-1, 1] to normalised latents.
    ///
    /// # Shapes
    /// `[b, 3, H, W] -> [b, C, s, s]`
    pub fn encode(&self, frames: Tensor<4>) -> Tensor<4> {
        let z = self.codec.encode(frames);
        let (m, s) = self.stat_tensors();
        (z - m) / s
    }

    /// Decodes normalised latents to frames (raw, nominally [-1, 1]); on the CPU with the
    /// direct kernels of [`CpuDecoder`] (several times faster than burn's convolutions here).
    ///
    /// # Shapes
    /// `[b, C, s, s] -> [b, 3, H, W]`
    pub fn decode(&self, z: Tensor<4>) -> Tensor<4> {
        if let Some(dec) = &self.cpu_decoder
            && let Ok(mut v) = z.clone().into_data().convert::<f32>().try_to_vec::<f32>()
        {
            let [b, c, s, _] = z.dims();
            let (mean, std) = (&self.cfg.latents.mean, &self.cfg.latents.std);
            for (i, x) in v.iter_mut().enumerate() {
                let ch = (i / (s * s)) % c;
                *x = *x * std[ch] + mean[ch];
            }
            let side = self.image_size();
            return Tensor::from_data(TensorData::new(dec.decode(&v, b), [b, 3, side, side]), &self.device);
        }
        let (m, s) = self.stat_tensors();
        self.codec.decode(z * s + m)
    }

    fn stat_tensors(&self) -> (Tensor<4>, Tensor<4>) {
        let c = self.cfg.latents.channels;
        let t = |v: &[f32]| Tensor::<1>::from_floats(v, &self.device).reshape([1, c, 1, 1]);
        (t(&self.cfg.latents.mean), t(&self.cfg.latents.std))
    }

    /// Sets the action-accentuation strength α used from now on (spec §3).
    ///
    /// # Errors
    /// [`SettingError`] when the model was not trained with accentuation or α is not a
    /// finite value >= 1.
    pub fn set_alpha(&mut self, alpha: f32) -> Result<(), SettingError> {
        if !self.cfg.unet.uses_accentuation() {
            return Err(SettingError::NoAlphaInput);
        }
        if !(alpha.is_finite() && alpha >= 1.0) {
            return Err(SettingError::Alpha(alpha));
        }
        self.cfg.alpha = Some(alpha);
        Ok(())
    }

    /// The action-accentuation strength α in effect: the configured one, else 1, for a
    /// model trained with accentuation; `None` for one without an α input.
    pub fn alpha(&self) -> Option<f32> {
        self.cfg.unet.uses_accentuation().then(|| self.cfg.alpha.unwrap_or(1.0))
    }

    /// Sets the sampling noise's scale ([`WorldModelConfig::noise_scale`]).
    ///
    /// # Errors
    /// A diffusion model (its noise is the DDIM trajectory's start, not a
    /// temperature), or a scale that is not a finite value in [0, 1].
    pub fn set_noise_scale(&mut self, scale: f32) -> Result<(), SettingError> {
        if self.cfg.objective == Objective::Diffusion {
            return Err(SettingError::NoTemperature);
        }
        if !(scale.is_finite() && (0.0..=1.0).contains(&scale)) {
            return Err(SettingError::NoiseScale(scale));
        }
        self.cfg.noise_scale = Some(scale);
        Ok(())
    }

    /// The sampling-noise scale in effect: the configured one, else 1.
    pub fn noise_scale(&self) -> f32 {
        self.cfg.noise_scale.unwrap_or(1.0)
    }

    /// Whether the U-Net reads the anchor (the episode's first frame) passed to
    /// [`Self::predict`]; other models ignore it.
    pub fn uses_anchor(&self) -> bool {
        self.cfg.unet.uses_anchor()
    }

    /// Predicts the next F latent frames in latent space.
    ///
    /// # Shapes
    /// - `history`: `[b, K, C, s, s]` normalised latents
    /// - `anchor`: `[b, C, s, s]` the normalised latents of each episode's first
    ///   observed frame (read only by anchored models)
    /// - `actions`: `[b, F, 2]` normalised actions (F ≤ the configured future)
    /// - returns `[b, F, C, s, s]`
    pub fn predict(
        &self,
        history: Tensor<5>,
        anchor: Tensor<4>,
        actions: Tensor<3>,
        rngs: &mut [Rng],
    ) -> Tensor<5> {
        let [b, _, c, s, _] = history.dims();
        let [_, f, _] = actions.dims();
        let hist = history.swap_dims(1, 2); // [b, C, K, s, s]
        let anchor = self.uses_anchor().then_some(anchor);
        let mut noise = row_noise(rngs, c * f * s * s);
        // The draws are made at any scale, so each row's RNG stream stays the same.
        let t = self.noise_scale();
        if t != 1.0 {
            noise.iter_mut().for_each(|v| *v *= t);
        }
        let x = Tensor::<5>::from_data(TensorData::new(noise, [b, c, f, s, s]), &self.device);
        let out = match self.cfg.objective {
            Objective::Drifting | Objective::Mse => self.unet_forward(x, hist, actions, anchor, None),
            Objective::Diffusion => self.ddim(x, hist, actions, anchor),
        };
        out.swap_dims(1, 2) // [b, F, C, s, s]
    }

    /// One U-Net pass ([`UNet::forward`]), on the CPU kernels of [`CpuUNet`] when the
    /// model has them.
    fn unet_forward(
        &self,
        noise: Tensor<5>,
        hist: Tensor<5>,
        actions: Tensor<3>,
        anchor: Option<Tensor<4>>,
        timestep: Option<Tensor<1>>,
    ) -> Tensor<5> {
        let b = noise.dims()[0];
        let alpha = self.alpha().map(|a| Tensor::<1>::full([b], a, &self.device));
        let Some(cpu) = &self.cpu_unet else {
            return self.unet.forward_accentuated(noise, hist, actions, anchor, timestep, alpha);
        };
        let out_dims = noise.dims();
        let emb = self.unet.embedding(actions.clone(), timestep.clone(), alpha.clone()); // [b, F, e]
        let x = self.unet.inputs(noise.clone(), hist.clone(), actions.clone(), anchor.clone()); // [b, c_in, F, h, w]
        let dims = x.dims();
        let as_vec = |d: TensorData| d.convert::<f32>().try_to_vec::<f32>();
        match (as_vec(x.into_data()), as_vec(emb.into_data())) {
            (Ok(x), Ok(emb)) => {
                Tensor::from_data(TensorData::new(cpu.forward(&x, &emb, dims), out_dims), &self.device)
            }
            _ => self.unet.forward_accentuated(noise, hist, actions, anchor, timestep, alpha),
        }
    }

    /// Deterministic DDIM from t = 1 to 0 in `sample_steps` steps. Every t < 1 step
    /// has ᾱ(t) < 1, so recovering ε from an x0 prediction never divides by zero.
    fn ddim(
        &self,
        mut x: Tensor<5>,
        hist: Tensor<5>,
        actions: Tensor<3>,
        anchor: Option<Tensor<4>>,
    ) -> Tensor<5> {
        let k = self.cfg.sample_steps.max(1);
        let b = x.dims()[0];
        for i in 0..k {
            let (t, t_next) = (1.0 - i as f64 / k as f64, 1.0 - (i + 1) as f64 / k as f64);
            let (a, a_next) = (alpha_bar(t), alpha_bar(t_next));
            let tt = Tensor::<1>::from_floats(vec![t as f32; b].as_slice(), &self.device);
            let out = self.unet_forward(x.clone(), hist.clone(), actions.clone(), anchor.clone(), Some(tt));
            let (x0, eps) = match self.cfg.prediction.unwrap_or_default() {
                Prediction::V => {
                    let x0 = x.clone() * a.sqrt() - out.clone() * (1.0 - a).sqrt();
                    (x0, x * (1.0 - a).sqrt() + out * a.sqrt())
                }
                Prediction::X0 => {
                    let eps = (x - out.clone() * a.sqrt()) / (1.0 - a).sqrt();
                    (out, eps)
                }
            };
            x = x0 * a_next.sqrt() + eps * (1.0 - a_next).sqrt();
        }
        x
    }
}

#[cfg(test)]
mod tests;
