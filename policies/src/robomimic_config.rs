//! What a robomimic diffusion-policy checkpoint says besides its weights: the `config` JSON
//! string (the fields inference depends on), `shape_metadata`, `env_metadata`, the
//! normalisation statistics, and the settings [`crate::import_robomimic`] supports, anything
//! else refused naming the field.
//!
//! The config is robomimic's own training config, of which inference reads a few fields; the
//! rest are its training settings, so unknown fields are ignored here (unlike evalharness's own
//! configs). Absent fields take robomimic's defaults (a `core_kwargs` of `{}` means a
//! ResNet18Conv, a SpatialSoftmax of 32 keypoints, 64 features). Statistics are per key
//! `{"scale": [[…]], "offset": [[…]]}` as nested lists; robomimic normalises with
//! `(x − offset) / scale`, which is the min-max map of min = offset − scale, max = offset +
//! scale that evalharness's [`Range`] applies.

use std::collections::BTreeMap;
use std::path::Path;

use nn::ImportError;
use pytorch_reader::{PickleValue, PytorchReader};
use serde::Deserialize;

use crate::diffusion::Range;

/// `algo.horizon`.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct Horizon {
    pub(crate) observation_horizon: usize,
    pub(crate) action_horizon: usize,
    pub(crate) prediction_horizon: usize,
}

/// `algo.ddpm` or `algo.ddim`.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct Scheduler {
    pub(crate) enabled: bool,
    pub(crate) num_train_timesteps: usize,
    pub(crate) num_inference_timesteps: usize,
    pub(crate) beta_schedule: String,
    pub(crate) clip_sample: bool,
    pub(crate) prediction_type: String,
    #[serde(default = "yes")]
    pub(crate) set_alpha_to_one: bool,
    #[serde(default)]
    pub(crate) steps_offset: usize,
}

fn yes() -> bool {
    true
}

/// `algo.ema`.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct Ema {
    #[serde(default)]
    pub(crate) enabled: bool,
}

/// `algo`.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct Algo {
    pub(crate) horizon: Horizon,
    #[serde(default)]
    pub(crate) ema: Ema,
    pub(crate) ddpm: Option<Scheduler>,
    pub(crate) ddim: Option<Scheduler>,
}

/// `observation.modalities.obs`.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct Modalities {
    #[serde(default)]
    pub(crate) low_dim: Vec<String>,
    #[serde(default)]
    pub(crate) rgb: Vec<String>,
    #[serde(default)]
    pub(crate) depth: Vec<String>,
    #[serde(default)]
    pub(crate) scan: Vec<String>,
}

/// `core_kwargs.backbone_kwargs`: the setting the importer refuses when on.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct BackboneKwargs {
    #[serde(default)]
    pub(crate) input_coord_conv: bool,
}

/// `core_kwargs.pool_kwargs`: the setting the importer refuses when on.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct PoolKwargs {
    #[serde(default)]
    pub(crate) output_variance: bool,
}

/// `observation.encoder.rgb.core_kwargs` (robomimic's defaults where absent).
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct CoreKwargs {
    pub(crate) backbone_class: Option<String>,
    #[serde(default)]
    pub(crate) backbone_kwargs: BackboneKwargs,
    pub(crate) pool_class: Option<String>,
    #[serde(default)]
    pub(crate) pool_kwargs: PoolKwargs,
}

/// `observation.encoder.rgb.obs_randomizer_kwargs` for a `CropRandomizer`.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct CropKwargs {
    pub(crate) crop_height: Option<usize>,
    pub(crate) crop_width: Option<usize>,
    pub(crate) num_crops: Option<usize>,
    pub(crate) pos_enc: Option<bool>,
}

/// `observation.encoder.rgb`.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct RgbEncoder {
    pub(crate) core_class: Option<String>,
    #[serde(default)]
    pub(crate) core_kwargs: CoreKwargs,
    pub(crate) obs_randomizer_class: Option<String>,
    #[serde(default)]
    pub(crate) obs_randomizer_kwargs: CropKwargs,
}

/// `observation`.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct Observation {
    pub(crate) modalities: ObsGroups,
    #[serde(default)]
    pub(crate) encoder: Encoders,
}

/// `observation.modalities`.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct ObsGroups {
    pub(crate) obs: Modalities,
}

/// `observation.encoder`.
#[derive(Clone, Debug, Default, Deserialize)]
pub(crate) struct Encoders {
    #[serde(default)]
    pub(crate) rgb: RgbEncoder,
}

/// The `config` fields inference depends on.
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct RobomimicConfig {
    pub(crate) algo: Algo,
    pub(crate) observation: Observation,
}

/// Everything of a checkpoint but its weights.
pub(crate) struct Meta {
    pub(crate) config: RobomimicConfig,
    /// `shape_metadata.all_shapes`: each observation key's shape (images CHW).
    pub(crate) shapes: BTreeMap<String, Vec<usize>>,
    /// `env_metadata.env_name`, where recorded.
    pub(crate) env_name: Option<String>,
    /// `action_normalization_stats` as a range (absent: none stored).
    pub(crate) action: Option<Range>,
    /// `obs_normalization_stats` per key (absent: none stored).
    pub(crate) obs: Option<BTreeMap<String, Range>>,
    /// `variable_state.epoch`.
    pub(crate) epoch: Option<i64>,
}

fn layout(path: &Path, what: String) -> ImportError {
    ImportError::Layout { path: path.into(), what }
}

fn top(path: &Path, key: &str) -> Result<PickleValue, ImportError> {
    PytorchReader::read_pickle_data(path, Some(key)).map_err(|e| layout(path, format!("`{key}`: {e}")))
}

fn numbers(v: &PickleValue) -> Option<Vec<f64>> {
    match v {
        PickleValue::List(items) => {
            let mut out = Vec::new();
            for i in items {
                match i {
                    PickleValue::Float(f) => out.push(*f),
                    PickleValue::Int(n) => out.push(*n as f64),
                    PickleValue::List(_) => out.extend(numbers(i)?),
                    _ => return None,
                }
            }
            Some(out)
        }
        _ => None,
    }
}

/// A `{"scale": [[…]], "offset": [[…]]}` entry as the range min = offset − scale, max = offset
/// + scale.
fn range_of(path: &Path, what: &str, v: &PickleValue) -> Result<Range, ImportError> {
    let PickleValue::Dict(d) = v else { return Err(layout(path, format!("`{what}` is not a dict"))) };
    let get = |k: &str| {
        d.get(k)
            .and_then(numbers)
            .ok_or_else(|| layout(path, format!("`{what}.{k}` is missing or not a list of numbers")))
    };
    let (scale, offset) = (get("scale")?, get("offset")?);
    if scale.len() != offset.len()
        || scale.iter().chain(&offset).any(|x| !x.is_finite())
        || scale.iter().any(|s| *s <= 0.0)
    {
        return Err(layout(
            path,
            format!("`{what}`: scale and offset must be finite, of one length, scale > 0"),
        ));
    }
    Ok(Range {
        min: offset.iter().zip(&scale).map(|(o, s)| (o - s) as f32).collect(),
        max: offset.iter().zip(&scale).map(|(o, s)| (o + s) as f32).collect(),
    })
}

fn stats(path: &Path, key: &str) -> Result<Option<BTreeMap<String, Range>>, ImportError> {
    match PytorchReader::read_pickle_data(path, Some(key)) {
        Ok(PickleValue::Dict(d)) => d
            .iter()
            .map(|(k, v)| Ok((k.clone(), range_of(path, &format!("{key}.{k}"), v)?)))
            .collect::<Result<BTreeMap<_, _>, _>>()
            .map(Some),
        Ok(PickleValue::None) | Err(_) => Ok(None),
        Ok(_) => Err(layout(path, format!("`{key}` is not a dict"))),
    }
}

/// Reads `algo_name`, `config`, `shape_metadata`, `env_metadata`, the statistics and the epoch.
///
/// # Errors
/// [`ImportError`] naming the file and entry: not a diffusion policy, a config that is not
/// robomimic's JSON, metadata that is not a dict (several datasets' lists are refused).
pub(crate) fn read(path: &Path) -> Result<Meta, ImportError> {
    match top(path, "algo_name")? {
        PickleValue::String(a) if a == "diffusion_policy" => {}
        other => return Err(layout(path, format!("`algo_name` is {other:?}, not \"diffusion_policy\""))),
    }
    let PickleValue::String(text) = top(path, "config")? else {
        return Err(layout(path, "`config` is not a JSON string".into()));
    };
    let config: RobomimicConfig = serde_json::from_str(&text)
        .map_err(|e| layout(path, format!("`config`: not a robomimic config: {e}")))?;
    let PickleValue::Dict(meta) = top(path, "shape_metadata")? else {
        return Err(layout(
            path,
            "`shape_metadata` is not a dict (a policy of several datasets is not supported)".into(),
        ));
    };
    let Some(PickleValue::Dict(all)) = meta.get("all_shapes") else {
        return Err(layout(path, "`shape_metadata.all_shapes` is missing".into()));
    };
    let shapes = all
        .iter()
        .map(|(k, v)| {
            let s = numbers(v).filter(|s| s.iter().all(|x| *x >= 0.0 && x.fract() == 0.0));
            s.map(|s| (k.clone(), s.iter().map(|x| *x as usize).collect()))
                .ok_or_else(|| layout(path, format!("`shape_metadata.all_shapes.{k}` is not a shape")))
        })
        .collect::<Result<BTreeMap<_, _>, _>>()?;
    let env_name = match PytorchReader::read_pickle_data(path, Some("env_metadata")) {
        Ok(PickleValue::Dict(d)) => match d.get("env_name") {
            Some(PickleValue::String(s)) => Some(s.clone()),
            _ => None,
        },
        _ => None,
    };
    let action = match stats(path, "action_normalization_stats")? {
        None => None,
        Some(m) if m.len() == 1 => m.into_values().next(),
        Some(m) => {
            return Err(layout(
                path,
                format!("`action_normalization_stats` has {} action keys; one is supported", m.len()),
            ));
        }
    };
    let obs = stats(path, "obs_normalization_stats")?;
    let epoch = match PytorchReader::read_pickle_data(path, Some("variable_state")) {
        Ok(PickleValue::Dict(d)) => match d.get("epoch") {
            Some(PickleValue::Int(e)) => Some(*e),
            _ => None,
        },
        _ => None,
    };
    Ok(Meta { config, shapes, env_name, action, obs, epoch })
}
