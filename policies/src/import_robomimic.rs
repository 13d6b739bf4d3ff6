//! robomimic's diffusion policies (`algo_name: diffusion_policy`, a `.pth` saved by its
//! `TrainUtils.save_model`, robomimic 0.5 and later) as `robomimic-diffusion` policies
//! ([`crate::imported_policy`]).
//!
//! The file is a pickled dict: `model` (`nets`, `ema`: two state dicts of the same keys,
//! `policy.obs_encoder.*` and `policy.noise_pred_net.*`), `config` (robomimic's training config
//! as a JSON string), `shape_metadata`, `env_metadata` and the normalisation statistics
//! ([`crate::robomimic_config`]). Inference runs the EMA copy when the config enables EMA, as
//! robomimic's rollouts do.
//!
//! Supported: one camera, `agentview_image` (what a world model imagines; an eye-in-hand
//! camera cannot be imagined and is refused by name), encoded by robomimic's VisualCore
//! (torchvision's ResNet-18 with every BatchNorm a GroupNorm(C/16), a SpatialSoftmax whose
//! temperature is folded into its 1×1 convolution, a Linear and the encoder's ReLU), optionally
//! centre-cropped; low-dimensional keys read raw or with the stored statistics from the task's
//! robot state ([`harness::task::ObservationSpec::robot`], checked when the policy loads);
//! features concatenated in the keys' alphabetical order, frame by frame; DDPM over every
//! training step or DDIM, squared-cosine betas, ε-prediction, clipped samples. robomimic
//! stores each backbone and pool tensor twice (`backbone.*` and `nets.0.*`, `pool.*` and
//! `nets.1.*`): the copies must be equal. Frames rendered at another size than the policy's
//! (robomimic's 84 against evalharness's 96) are resized bilinearly. Anything else is refused
//! naming the file and the key or config field.

use std::collections::BTreeMap;
use std::path::Path;

use burn::tensor::Device;
use nn::ImportError;
use nn::import::place::{place_all, shapes};
use nn::import::tensors::Source;

use crate::diffusion::{Normalisation, Range};
use crate::import_keys::{UnetSizes, unet_sizes};
use crate::imported_policy::{ImportedConfig, ImportedNet, Pool, Prediction, Sampler, centre_offset};
use crate::net::NetConfig;
use crate::resnet_gn::BackboneNorm;
use crate::robomimic_config::{Meta, RobomimicConfig, read};
#[cfg(test)]
use crate::robomimic_weights::burn_path;
use crate::robomimic_weights::{ENCODER, UNET, expected_names, layout, weights_of};

/// The one camera key imported policies may read.
pub const IMAGE_KEY: &str = "agentview_image";

/// Which copy of the weights to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobomimicWeights {
    /// What robomimic's rollouts run: `model.ema` when the config enables EMA, else `model.nets`.
    Ema,
    /// `model.nets` (the raw training weights).
    Model,
}

/// An imported robomimic policy.
pub struct RobomimicPolicy {
    /// The networks.
    pub net: ImportedNet,
    /// Sizes and settings.
    pub cfg: ImportedConfig,
    /// The low-dimensional keys' and the action's ranges.
    pub norm: Normalisation,
    /// Weight tensors placed.
    pub tensors: usize,
    /// The state dict read (`model.ema` or `model.nets`).
    pub weights: &'static str,
    /// `variable_state.epoch`, if recorded.
    pub epoch: Option<i64>,
    /// `env_metadata.env_name`, if recorded (`Lift`, `PickPlaceCan`).
    pub env_name: Option<String>,
}

/// The observation keys, checked: one `agentview_image` and low-dimensional keys, alphabetical.
/// Returns the low-dimensional keys and whether the image sorts after them.
fn keys(c: &RobomimicConfig, path: &Path) -> Result<(Vec<String>, bool), ImportError> {
    let m = &c.observation.modalities.obs;
    if let Some(k) = m.depth.iter().chain(&m.scan).next() {
        return Err(layout(
            path,
            format!("`config` observation key `{k}`: depth and scan observations are not supported"),
        ));
    }
    if let Some(k) = m.rgb.iter().find(|k| *k != IMAGE_KEY) {
        return Err(layout(
            path,
            format!(
                "`config` observation key `{k}`: only `{IMAGE_KEY}` can be given (a world model imagines that camera alone)"
            ),
        ));
    }
    if m.rgb.is_empty() {
        return Err(layout(
            path,
            format!(
                "`config` reads no `{IMAGE_KEY}`: a low-dimensional policy cannot be ranked in a world model"
            ),
        ));
    }
    let mut low = m.low_dim.clone();
    low.sort();
    let (before, after) =
        (low.iter().any(|k| k.as_str() < IMAGE_KEY), low.iter().any(|k| k.as_str() > IMAGE_KEY));
    if before && after {
        return Err(layout(
            path,
            format!(
                "`config` has low-dimensional keys on both sides of `{IMAGE_KEY}` alphabetically ({low:?})"
            ),
        ));
    }
    Ok((low, before))
}

/// The sampler and its step counts, checked.
fn sampler(
    c: &RobomimicConfig,
    path: &Path,
) -> Result<(Sampler, Prediction, usize, Option<usize>), ImportError> {
    let (s, which) = match (&c.algo.ddpm, &c.algo.ddim) {
        (Some(s), _) if s.enabled => (s, Sampler::Ddpm),
        (_, Some(s)) if s.enabled => (s, Sampler::Ddim),
        _ => return Err(layout(path, "`config` algo: neither ddpm nor ddim is enabled".into())),
    };
    let field = if which == Sampler::Ddpm { "algo.ddpm" } else { "algo.ddim" };
    let bad = |f: &str, v: String| layout(path, format!("`config` {field}.{f} = {v}: not supported"));
    if s.beta_schedule != "squaredcos_cap_v2" {
        return Err(bad("beta_schedule", s.beta_schedule.clone()));
    }
    let prediction = match s.prediction_type.as_str() {
        "epsilon" => Prediction::Epsilon,
        "sample" => Prediction::Sample,
        other => return Err(bad("prediction_type", other.to_string())),
    };
    if !s.clip_sample {
        return Err(bad("clip_sample", "false".into()));
    }
    let (n, t) = (s.num_inference_timesteps, s.num_train_timesteps);
    if t == 0 || n == 0 || n > t {
        return Err(bad("num_inference_timesteps", format!("{n} of {t}")));
    }
    match which {
        // diffusers 0.11.1 (robomimic's) steps DDPM to t − 1 whatever the spacing: only
        // every step is the same sampler as evalharness's.
        Sampler::Ddpm if n != t => {
            Err(bad("num_inference_timesteps", format!("{n} of {t} (DDPM over every step only)")))
        }
        Sampler::Ddim if !s.set_alpha_to_one || s.steps_offset != 0 => {
            Err(bad("set_alpha_to_one/steps_offset", format!("{}/{}", s.set_alpha_to_one, s.steps_offset)))
        }
        _ => Ok((which, prediction, t, (n != t).then_some(n))),
    }
}

/// The encoder's settings other than sizes: the crop (if any), checked against what is supported.
fn crop(c: &RobomimicConfig, path: &Path) -> Result<Option<usize>, ImportError> {
    let rgb = &c.observation.encoder.rgb;
    let core = &rgb.core_kwargs;
    let unsupported = |f: &str, v: String| {
        layout(path, format!("`config` observation.encoder.rgb.{f} = {v}: not supported"))
    };
    if let Some(v) = rgb.core_class.as_deref().filter(|v| *v != "VisualCore") {
        return Err(unsupported("core_class", v.into()));
    }
    if let Some(v) = core.backbone_class.as_deref().filter(|v| *v != "ResNet18Conv") {
        return Err(unsupported("core_kwargs.backbone_class", v.into()));
    }
    if let Some(v) = core.pool_class.as_deref().filter(|v| *v != "SpatialSoftmax") {
        return Err(unsupported("core_kwargs.pool_class", v.into()));
    }
    if core.backbone_kwargs.input_coord_conv {
        return Err(unsupported("core_kwargs.backbone_kwargs.input_coord_conv", "true".into()));
    }
    if core.pool_kwargs.output_variance {
        return Err(unsupported("core_kwargs.pool_kwargs.output_variance", "true".into()));
    }
    match rgb.obs_randomizer_class.as_deref() {
        None => Ok(None),
        Some("CropRandomizer") => {
            let k = &rgb.obs_randomizer_kwargs;
            let (h, w) = (k.crop_height.unwrap_or(76), k.crop_width.unwrap_or(76));
            if h != w || k.num_crops.unwrap_or(1) != 1 || k.pos_enc.unwrap_or(false) {
                return Err(unsupported(
                    "obs_randomizer_kwargs",
                    format!("{h}x{w}, {:?} crops, pos_enc {:?}", k.num_crops, k.pos_enc),
                ));
            }
            Ok(Some(h))
        }
        Some(other) => Err(unsupported("obs_randomizer_class", other.into())),
    }
}

/// The low-dimensional keys' range: the stored statistics, or none (the identity, [-1, 1]).
fn state_range(meta: &Meta, low: &[String], path: &Path) -> Result<Range, ImportError> {
    let mut r = Range { min: Vec::new(), max: Vec::new() };
    if meta.obs.as_ref().is_some_and(|o| o.contains_key(IMAGE_KEY)) {
        return Err(layout(
            path,
            format!("`obs_normalization_stats.{IMAGE_KEY}`: normalised images are not supported"),
        ));
    }
    for k in low {
        let w = meta.shapes.get(k).map(|s| s.iter().product::<usize>()).ok_or_else(|| {
            layout(path, format!("`shape_metadata.all_shapes` lacks the observation key `{k}`"))
        })?;
        match meta.obs.as_ref().map(|o| o.get(k)) {
            Some(Some(s)) if s.dim() == w => {
                r.min.extend(&s.min);
                r.max.extend(&s.max);
            }
            Some(Some(s)) => {
                return Err(layout(
                    path,
                    format!("`obs_normalization_stats.{k}` has {} entries, the key {w}", s.dim()),
                ));
            }
            Some(None) => return Err(layout(path, format!("`obs_normalization_stats` lacks `{k}`"))),
            None => {
                r.min.extend(std::iter::repeat_n(-1.0, w));
                r.max.extend(std::iter::repeat_n(1.0, w));
            }
        }
    }
    Ok(r)
}

/// What a checkpoint declares of the scene it was trained in, read without its weights.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Declared {
    /// Its low-dimensional observation keys, alphabetical (checked as [`import`] checks them).
    pub low_dim: Vec<String>,
    /// `env_metadata.env_name`, if recorded.
    pub env_name: Option<String>,
}

/// What `path` declares, so that a caller can match it to a scenario before importing.
///
/// # Errors
/// As [`import`] for the file's metadata and keys.
pub fn declared(path: &Path) -> Result<Declared, ImportError> {
    let meta = read(path)?;
    Ok(Declared { low_dim: keys(&meta.config, path)?.0, env_name: meta.env_name })
}

/// The side of the frames the checkpoint was trained on, with its crop checked to start
/// where torchvision's does (robomimic's eval-time crop starts at ⌊margin / 2⌋).
///
/// # Errors
/// A frame shape that is not square RGB, or a crop that starts elsewhere.
fn frame_side(meta: &Meta, crop: Option<usize>, path: &Path) -> Result<usize, ImportError> {
    let side = match meta.shapes.get(IMAGE_KEY).map(Vec::as_slice) {
        Some(&[3, hh, ww]) if hh == ww && hh > 0 => hh,
        other => {
            return Err(layout(
                path,
                format!("`shape_metadata.all_shapes.{IMAGE_KEY}` is {other:?}, expected [3, N, N]"),
            ));
        }
    };
    if let Some(c) = crop.filter(|&c| c > side || centre_offset(side - c) != (side - c) / 2) {
        return Err(layout(
            path,
            format!(
                "`config` crop {c} of {side}x{side} frames: a crop starting at another pixel than torchvision's is not supported"
            ),
        ));
    }
    Ok(side)
}

/// The state and action normalisation ranges, checked against the U-Net's widths
/// (`state`, `action`); actions without statistics are taken as [-1, 1].
///
/// # Errors
/// Ranges of another width than the U-Net's.
fn normalisation_of(
    meta: &Meta,
    low: &[String],
    (state, action): (usize, usize),
    path: &Path,
) -> Result<Normalisation, ImportError> {
    let state_norm = state_range(meta, low, path)?;
    if state_norm.dim() != state {
        return Err(layout(
            path,
            format!(
                "the low-dimensional keys {low:?} have {} entries, the U-Net reads {state}",
                state_norm.dim()
            ),
        ));
    }
    let action_norm =
        meta.action.clone().unwrap_or(Range { min: vec![-1.0; action], max: vec![1.0; action] });
    if action_norm.dim() != action {
        return Err(layout(
            path,
            format!(
                "`action_normalization_stats` has {} entries, the U-Net acts in {action}",
                action_norm.dim()
            ),
        ));
    }
    Ok(Normalisation { agent_pos: state_norm, action: action_norm })
}

/// Imports a robomimic diffusion-policy checkpoint for a scenario rendering `scene_size`² frames.
///
/// # Errors
/// [`ImportError`] naming the file and the key or config field for anything missing,
/// unexpected, mis-shaped, non-float32 or non-finite, a duplicate that differs, a grid or
/// temperature that is not robomimic's, or a setting that is not supported.
pub fn import(
    path: &Path,
    weights: RobomimicWeights,
    scene_size: usize,
    device: &Device,
) -> Result<RobomimicPolicy, ImportError> {
    let meta = read(path)?;
    let c = &meta.config;
    let (low, image_last) = keys(c, path)?;
    let (sampler, prediction, train_steps, inference_steps) = sampler(c, path)?;
    let crop = crop(c, path)?;
    let side = frame_side(&meta, crop, path)?;
    let use_ema = weights == RobomimicWeights::Ema && c.algo.ema.enabled;
    let (prefix, which) = if use_ema { ("ema.", "model.ema") } else { ("nets.", "model.nets") };
    let src = Source::open(path, Some("model"), prefix)?;
    let s = src.shapes();
    let enc = format!("{ENCODER}{IMAGE_KEY}.");
    let shape = |k: &str| {
        s.get(k).cloned().ok_or_else(|| ImportError::Missing { path: path.into(), key: src.shown(k) })
    };
    let base = match shape(&format!("{enc}backbone.nets.0.weight"))?.as_slice() {
        &[b, 3, 7, 7] if b > 0 && b % 16 == 0 => b,
        other => {
            return Err(layout(
                path,
                format!(
                    "`{}` has shape {other:?}, expected [64, 3, 7, 7]",
                    src.shown(&format!("{enc}backbone.nets.0.weight"))
                ),
            ));
        }
    };
    let keypoints = shape(&format!("{enc}pool.nets.weight"))?[0];
    let features = shape(&format!("{enc}nets.3.weight"))?[0];
    let unet: BTreeMap<String, Vec<usize>> =
        s.iter().filter_map(|(k, v)| Some((k.strip_prefix(UNET)?.to_string(), v.clone()))).collect();
    let UnetSizes { dims, action, kernel, step_embed, cond } =
        unet_sizes(&unet, "blocks.0", path, &src.shown(UNET))?;
    let h = &c.algo.horizon;
    let o = h.observation_horizon.max(1);
    let state = (cond % o == 0).then(|| (cond / o).checked_sub(features)).flatten().ok_or_else(|| {
        layout(path, format!("conditioning of {cond} entries is not {o} frames of {features} features plus low-dimensional keys"))
    })?;
    let norm = normalisation_of(&meta, &low, (state, action), path)?;
    let cfg = ImportedConfig {
        resnet_base: base,
        backbone_norm: BackboneNorm::Group,
        pool: Pool::SpatialSoftmax { keypoints, features: Some(features) },
        input_size: (side != scene_size).then_some(side),
        antialias: false,
        crop,
        image_norm: None,
        position_first: image_last,
        robot_keys: low.clone(),
        inference_steps,
        sampler,
        prediction,
        net: NetConfig {
            image_size: scene_size,
            encoder_width: base,
            feature_dim: features,
            down_dims: dims,
            kernel,
            step_embed,
            obs_horizon: o,
            action_dim: action,
            proprio_dim: Some(state),
        },
        horizon: h.prediction_horizon,
        action_horizon: h.action_horizon,
        train_steps,
    };
    if cfg.action_horizon == 0
        || cfg.action_horizon > cfg.max_action_horizon()
        || !cfg.horizon.is_multiple_of(4)
    {
        return Err(layout(
            path,
            format!(
                "`config` algo.horizon {}/{}/{} does not fit a U-Net of two resamplings",
                o, h.action_horizon, h.prediction_horizon
            ),
        ));
    }
    if let Some(n) = expected_names(&enc, &cfg.net.down_dims, action).iter().find(|n| !s.contains_key(*n)) {
        return Err(ImportError::Missing { path: path.into(), key: src.shown(n) });
    }
    let net = ImportedNet::new(&cfg, device);
    let (values, tensors) = weights_of(&src, &enc, &shapes(&net))?;
    let net = place_all(net, values, path)?;
    Ok(RobomimicPolicy {
        net,
        cfg,
        norm,
        tensors,
        weights: which,
        epoch: meta.epoch,
        env_name: meta.env_name,
    })
}

#[cfg(test)]
#[path = "import_robomimic_tests.rs"]
mod tests;
