//! LeRobot's diffusion policies (`type: diffusion`, a `pretrained_model/` folder) as
//! `lerobot-diffusion` policies ([`crate::imported_policy`]).
//!
//! The folder holds `config.json` (LeRobot's 2025 format with `input_features` and
//! `normalization_mapping`, or its 2024 one with `input_shapes` and `*_normalization_modes`) and
//! `model.safetensors` (`diffusion.rgb_encoder.*`, `diffusion.unet.*`). The normalisation
//! statistics are in `model.safetensors` (`normalize_inputs.buffer_*`, LeRobot before 0.4) or
//! in the preprocessor's `policy_preprocessor_step_*_normalizer_processor.safetensors` (0.4 and
//! later). Supported: one camera with LeRobot's Push-T settings (a ResNet-18 with GroupNorm
//! trained from scratch, or with its BatchNorms as torchvision has them, `use_group_norm:
//! false`, usually from ImageNet weights, folded into the convolutions at import; a spatial
//! softmax, a centre crop, FiLM with scale, DDPM or DDIM on the squared-cosine schedule, ε- or
//! x₀-prediction, clipped samples); anything else is refused naming the `config.json` field.
//! Weights are mapped key by key ([`burn_path`]); a missing, unexpected, mis-shaped, non-float32
//! or non-finite tensor is refused naming the file and key.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use burn::tensor::{Device, TensorData};
use nn::ImportError;
use nn::import::place::{place_all, shapes, transpose};
use nn::import::safe::SafeSource;

use crate::diffusion::{Normalisation, Range};
use crate::import_keys::{UnetNames, cond_unet, resnet_children};
use crate::imported_policy::{ImportedConfig, ImportedNet, MeanStd, Pool, Prediction, Sampler};
use crate::lerobot_config::{LeRobotConfig, check, features};
use crate::net::NetConfig;
use crate::resnet::{ConvSite, batch_norm_sites, fold_batch_norm};
use crate::resnet_gn::BackboneNorm;

/// An imported LeRobot policy: networks, config, statistics and what was read.
pub struct LeRobotPolicy {
    /// The networks.
    pub net: ImportedNet,
    /// Their sizes and settings.
    pub cfg: ImportedConfig,
    /// The state's and the action's ranges.
    pub norm: Normalisation,
    /// Weight tensors read.
    pub tensors: usize,
    /// Where the statistics came from.
    pub stats_from: PathBuf,
}

/// evalharness's path of a LeRobot key (without `diffusion.`), and whether it is a Linear
/// weight (transposed); `None` for a key with no place.
pub fn burn_path(key: &str) -> Option<(String, bool)> {
    if let Some(r) = key.strip_prefix("rgb_encoder.") {
        if let Some(p) = r.strip_prefix("pool.nets.") {
            return Some((format!("head.nets.{p}"), false));
        }
        if let Some(p) = r.strip_prefix("out.") {
            return Some((format!("head.out.{p}"), p == "weight"));
        }
        return resnet_children(r.strip_prefix("backbone.")?);
    }
    cond_unet(key.strip_prefix("unet.")?, &UnetNames { convs: ["conv1", "conv2"], resample: "" })
}

/// Keys LeRobot stores beside the weights: the spatial softmax's grid (recomputed here) and,
/// before 0.4, the normalisation statistics.
fn is_extra(key: &str) -> bool {
    key == "diffusion.rgb_encoder.pool.pos_grid"
        || ["normalize_inputs.", "normalize_targets.", "unnormalize_outputs."]
            .iter()
            .any(|p| key.starts_with(p))
}

/// The backbone's convolutions with their eval-mode BatchNorms folded in (LeRobot's
/// `use_group_norm: false`, torchvision's ResNet-18 as it is, often from ImageNet weights):
/// evalharness's values by path, and the file's keys they consumed (each BatchNorm's step
/// counter, an int64, is consumed unread).
fn folded_backbone(
    model: &SafeSource,
    ours: &BTreeMap<String, Vec<usize>>,
) -> Result<(BTreeMap<String, TensorData>, BTreeSet<String>), ImportError> {
    let keys: BTreeMap<String, String> =
        model.shapes().into_keys().map(|k| (k.replace("._orig_mod", ""), k)).collect();
    let (mut values, mut used) = (BTreeMap::new(), BTreeSet::new());
    for (conv, bn, site) in batch_norm_sites() {
        let (conv, bn) = (format!("backbone.{conv}"), format!("backbone.{bn}"));
        let to = match site {
            ConvSite::Stem => "encoder.stem.conv".to_string(),
            ConvSite::First(b) => format!("encoder.blocks.{b}.c1.conv"),
            ConvSite::Second(b) => format!("encoder.blocks.{b}.c2.conv"),
            ConvSite::Down(b) => format!("encoder.blocks.{b}.down.conv"),
        };
        let shape = ours[&format!("{to}.weight")].clone();
        let co = shape[0];
        let mut take = |name: &str, shape: &[usize]| -> Result<Vec<f32>, ImportError> {
            let short = format!("diffusion.rgb_encoder.{name}");
            let key = keys
                .get(&short)
                .ok_or_else(|| ImportError::Missing { path: model.path().into(), key: short })?;
            used.insert(key.clone());
            model.f32s(key, shape, false)
        };
        let mut w = take(&format!("{conv}.weight"), &shape)?;
        let gamma = take(&format!("{bn}.weight"), &[co])?;
        let beta = take(&format!("{bn}.bias"), &[co])?;
        let mean = take(&format!("{bn}.running_mean"), &[co])?;
        let var = take(&format!("{bn}.running_var"), &[co])?;
        let bias =
            fold_batch_norm(&mut w, &gamma, &beta, &mean, &var).map_err(|neg| ImportError::Layout {
                path: model.path().into(),
                what: format!("key `diffusion.rgb_encoder.{bn}.running_var` is negative at channel {neg}"),
            })?;
        if let Some(k) = keys.get(&format!("diffusion.rgb_encoder.{bn}.num_batches_tracked")) {
            used.insert(k.clone());
        }
        values.insert(format!("{to}.weight"), TensorData::new(w, shape));
        values.insert(format!("{to}.bias"), TensorData::new(bias, [co]));
    }
    Ok((values, used))
}

/// The statistics: from `model.safetensors`'s legacy entries, else from the preprocessor's file.
fn statistics(
    dir: &Path,
    model: &SafeSource,
    image: &str,
) -> Result<(MeanStd, Normalisation, PathBuf), ImportError> {
    let legacy = |k: &str| format!("normalize_inputs.buffer_{}", k.replace('.', "_"));
    let processor;
    let (src, names): (&SafeSource, [String; 6]) = if model.has(&format!("{}.mean", legacy(image))) {
        (
            model,
            [
                format!("{}.mean", legacy(image)),
                format!("{}.std", legacy(image)),
                format!("{}.min", legacy("observation.state")),
                format!("{}.max", legacy("observation.state")),
                "unnormalize_outputs.buffer_action.min".into(),
                "unnormalize_outputs.buffer_action.max".into(),
            ],
        )
    } else {
        let found = std::fs::read_dir(dir)
            .map_err(|source| ImportError::Io { path: dir.into(), key: "(the folder)".into(), source })?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .find(|p| {
                p.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
                    n.starts_with("policy_preprocessor") && n.contains("normalizer") && n.ends_with(".safetensors")
                })
            })
            .ok_or_else(|| ImportError::Missing {
                path: dir.into(),
                key: "normalisation statistics (normalize_inputs.* in model.safetensors, or a policy_preprocessor_*normalizer*.safetensors)".into(),
            })?;
        processor = SafeSource::open(&found)?;
        (
            &processor,
            [
                format!("{image}.mean"),
                format!("{image}.std"),
                "observation.state.min".into(),
                "observation.state.max".into(),
                "action.min".into(),
                "action.max".into(),
            ],
        )
    };
    let three = |k: &str| -> Result<[f32; 3], ImportError> {
        let v = src.f32s(k, &[3], true)?;
        Ok([v[0], v[1], v[2]])
    };
    let range = |lo: &str, hi: &str| -> Result<Range, ImportError> {
        let n = src.shapes().get(lo).map_or(0, |s| s.iter().product());
        Ok(Range { min: src.f32s(lo, &[n], true)?, max: src.f32s(hi, &[n], true)? })
    };
    let image_norm = MeanStd { mean: three(&names[0])?, std: three(&names[1])? };
    let norm =
        Normalisation { agent_pos: range(&names[2], &names[3])?, action: range(&names[4], &names[5])? };
    Ok((image_norm, norm, src.path().to_path_buf()))
}

/// A LeRobot diffusion `config.json`.
///
/// # Errors
/// An unreadable file, or one that is not a LeRobot diffusion config.
fn read_config(path: &Path) -> Result<LeRobotConfig, ImportError> {
    let text = std::fs::read_to_string(path).map_err(|source| ImportError::Io {
        path: path.to_path_buf(),
        key: "(the file)".into(),
        source,
    })?;
    serde_json::from_str(&text).map_err(|e| ImportError::Layout {
        path: path.to_path_buf(),
        what: format!("not a LeRobot diffusion config: {e}"),
    })
}

/// The ResNet's base width, from its first convolution's weight (a multiple of 16 under
/// GroupNorm's 16 groups).
///
/// # Errors
/// A missing first convolution, or one of another shape.
fn backbone_width(model: &SafeSource, group_norm: bool) -> Result<usize, ImportError> {
    match model.shapes().get("diffusion.rgb_encoder.backbone.0.weight").map(Vec::as_slice) {
        Some(&[b, 3, 7, 7]) if b > 0 && (b % 16 == 0 || !group_norm) => Ok(b),
        Some(s) => Err(ImportError::Shape {
            path: model.path().into(),
            key: "diffusion.rgb_encoder.backbone.0.weight".into(),
            found: s.to_vec(),
            expected: vec![64, 3, 7, 7],
        }),
        None => Err(ImportError::Missing {
            path: model.path().into(),
            key: "diffusion.rgb_encoder.backbone.0.weight".into(),
        }),
    }
}

/// Imports a LeRobot `pretrained_model/` folder.
///
/// # Errors
/// [`ImportError`] naming the file and the `config.json` field or key at fault.
pub fn import(dir: &Path, device: &Device) -> Result<LeRobotPolicy, ImportError> {
    let cfg_path = dir.join("config.json");
    let c = read_config(&cfg_path)?;
    check(&c, &cfg_path)?;
    let (image, shape, state, action) = features(&c, &cfg_path)?;
    let model = SafeSource::open(&dir.join("model.safetensors"))?;
    let base = backbone_width(&model, c.use_group_norm)?;
    let k = c.spatial_softmax_num_keypoints;
    let (image_norm, norm, stats_from) = statistics(dir, &model, &image)?;
    if norm.agent_pos.dim() != state || norm.action.dim() != action {
        return Err(ImportError::Layout {
            path: stats_from,
            what: format!(
                "statistics of {} state and {} action entries; config.json says {state} and {action}",
                norm.agent_pos.dim(),
                norm.action.dim()
            ),
        });
    }
    let (resize, crop) = crate::lerobot_config::resize_and_crop(&c);
    let backbone_norm = if c.use_group_norm { BackboneNorm::Group } else { BackboneNorm::FoldedBatch };
    let cfg = ImportedConfig {
        resnet_base: base,
        backbone_norm,
        pool: Pool::SpatialSoftmax { keypoints: k, features: None },
        input_size: resize,
        antialias: resize.is_some(),
        crop,
        image_norm: Some(image_norm),
        position_first: true,
        robot_keys: Vec::new(),
        inference_steps: c.num_inference_steps,
        sampler: if c.noise_scheduler_type == "DDIM" { Sampler::Ddim } else { Sampler::Ddpm },
        prediction: if c.prediction_type == "sample" { Prediction::Sample } else { Prediction::Epsilon },
        net: NetConfig {
            image_size: shape[1],
            encoder_width: base,
            feature_dim: 2 * k,
            down_dims: c.down_dims.clone(),
            kernel: c.kernel_size,
            step_embed: c.diffusion_step_embed_dim,
            obs_horizon: c.n_obs_steps,
            action_dim: action,
            proprio_dim: Some(state),
        },
        horizon: c.horizon,
        action_horizon: c.n_action_steps,
        train_steps: c.num_train_timesteps,
    };
    if cfg.action_horizon == 0 || cfg.action_horizon > cfg.max_action_horizon() {
        return Err(ImportError::Layout {
            path: cfg_path,
            what: format!(
                "n_action_steps {} does not fit horizon {} with {} observations",
                c.n_action_steps, c.horizon, c.n_obs_steps
            ),
        });
    }
    let net = ImportedNet::new(&cfg, device);
    let ours = shapes(&net);
    let (mut values, consumed) =
        if c.use_group_norm { Default::default() } else { folded_backbone(&model, &ours)? };
    let mut unexpected = Vec::new();
    for (key, theirs) in model.shapes() {
        if is_extra(&key) || consumed.contains(&key) {
            continue;
        }
        let short = key.replace("._orig_mod", "");
        let mapped =
            short.strip_prefix("diffusion.").and_then(burn_path).filter(|(to, _)| ours.contains_key(to));
        let Some((to, linear)) = mapped else {
            unexpected.push(key.clone());
            continue;
        };
        let want = &ours[&to];
        let expect = if linear { vec![want[1], want[0]] } else { want.clone() };
        let v = model.f32s(&key, &expect, false)?;
        let v = if linear { transpose(&v, theirs[1], theirs[0]) } else { v };
        values.insert(to, TensorData::new(v, want.clone()));
    }
    if !unexpected.is_empty() {
        return Err(ImportError::Unexpected { path: model.path().into(), keys: unexpected });
    }
    if let Some(missing) = ours.keys().find(|p| !values.contains_key(*p)) {
        return Err(ImportError::Missing {
            path: model.path().into(),
            key: format!("the weights of `{missing}`"),
        });
    }
    let tensors = values.len();
    let net = place_all(net, values, model.path())?;
    Ok(LeRobotPolicy { net, cfg, norm, tensors, stats_from })
}

#[cfg(test)]
#[path = "import_lerobot_tests.rs"]
mod tests;
