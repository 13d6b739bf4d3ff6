//! LeRobot's `config.json` for diffusion policies: the fields inference depends on (LeRobot's
//! 2025 format with `input_features` and `normalization_mapping`, or its 2024 one with
//! `input_shapes` and `*_normalization_modes`), the features they declare, and the settings
//! [`crate::import_lerobot`] supports, anything else refused naming the field.

use std::collections::BTreeMap;
use std::path::Path;

use nn::ImportError;
use serde::Deserialize;

/// A feature of LeRobot's 2025 config (`{"type": "VISUAL", "shape": [3, 96, 96]}`).
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct Feature {
    #[serde(rename = "type")]
    pub(crate) kind: String,
    pub(crate) shape: Vec<usize>,
}

/// The `config.json` fields inference depends on (other fields are LeRobot's training settings).
#[derive(Clone, Debug, Deserialize)]
pub(crate) struct LeRobotConfig {
    pub(crate) n_obs_steps: usize,
    pub(crate) horizon: usize,
    pub(crate) n_action_steps: usize,
    #[serde(default)]
    pub(crate) input_features: Option<BTreeMap<String, Feature>>,
    #[serde(default)]
    pub(crate) output_features: Option<BTreeMap<String, Feature>>,
    #[serde(default)]
    pub(crate) input_shapes: Option<BTreeMap<String, Vec<usize>>>,
    #[serde(default)]
    pub(crate) output_shapes: Option<BTreeMap<String, Vec<usize>>>,
    #[serde(default)]
    pub(crate) normalization_mapping: Option<BTreeMap<String, String>>,
    #[serde(default)]
    pub(crate) input_normalization_modes: Option<BTreeMap<String, String>>,
    #[serde(default)]
    pub(crate) output_normalization_modes: Option<BTreeMap<String, String>>,
    pub(crate) vision_backbone: String,
    #[serde(default)]
    pub(crate) crop_shape: Option<[usize; 2]>,
    #[serde(default)]
    pub(crate) resize_shape: Option<Vec<usize>>,
    /// The crop's share of `resize_shape` (LeRobot 0.4 on; absent: 1, no crop after a resize).
    #[serde(default)]
    pub(crate) crop_ratio: Option<f64>,
    pub(crate) use_group_norm: bool,
    pub(crate) spatial_softmax_num_keypoints: usize,
    #[serde(default)]
    pub(crate) use_separate_rgb_encoder_per_camera: bool,
    pub(crate) down_dims: Vec<usize>,
    pub(crate) kernel_size: usize,
    pub(crate) n_groups: usize,
    pub(crate) diffusion_step_embed_dim: usize,
    pub(crate) use_film_scale_modulation: bool,
    #[serde(default = "ddpm")]
    pub(crate) noise_scheduler_type: String,
    pub(crate) num_train_timesteps: usize,
    pub(crate) beta_schedule: String,
    pub(crate) prediction_type: String,
    pub(crate) clip_sample: bool,
    pub(crate) clip_sample_range: f64,
    #[serde(default)]
    pub(crate) num_inference_steps: Option<usize>,
}

fn ddpm() -> String {
    "DDPM".into()
}

/// Inputs by name (type, shape) and outputs by name (shape).
type Features = (BTreeMap<String, (String, Vec<usize>)>, BTreeMap<String, Vec<usize>>);

/// The image, state and action features: (image name, [c, h, w]), state width, action width.
pub(crate) fn features(
    c: &LeRobotConfig,
    path: &Path,
) -> Result<(String, Vec<usize>, usize, usize), ImportError> {
    let bad = |what: String| ImportError::Layout { path: path.into(), what };
    let (inputs, outputs): Features =
        match (&c.input_features, &c.output_features, &c.input_shapes, &c.output_shapes) {
            (Some(i), Some(o), _, _) => (
                i.iter().map(|(k, f)| (k.clone(), (f.kind.clone(), f.shape.clone()))).collect(),
                o.iter().map(|(k, f)| (k.clone(), f.shape.clone())).collect(),
            ),
            (_, _, Some(i), Some(o)) => (
                i.iter()
                    .map(|(k, s)| {
                        let kind = if k.starts_with("observation.image") { "VISUAL" } else { "STATE" };
                        (k.clone(), (kind.to_string(), s.clone()))
                    })
                    .collect(),
                o.clone(),
            ),
            _ => {
                return Err(bad(
                    "config.json has neither input_features/output_features nor input_shapes/output_shapes"
                        .into(),
                ));
            }
        };
    let images: Vec<(&String, &Vec<usize>)> =
        inputs.iter().filter(|(_, (k, _))| k == "VISUAL").map(|(n, (_, s))| (n, s)).collect();
    let [(image, shape)] = images.as_slice() else {
        return Err(bad(format!("config.json: {} camera inputs; one is supported", images.len())));
    };
    if shape.len() != 3 || shape[0] != 3 || shape[1] != shape[2] {
        return Err(bad(format!(
            "config.json: input `{image}` has shape {shape:?}; square RGB frames are supported"
        )));
    }
    let state = match inputs.get("observation.state") {
        Some((_, s)) if s.len() == 1 => s[0],
        _ => return Err(bad("config.json: no 1-D input `observation.state`".into())),
    };
    if let Some(other) = inputs.keys().find(|k| *k != *image && k.as_str() != "observation.state") {
        return Err(bad(format!(
            "config.json: input `{other}` is not supported (one camera and the state are)"
        )));
    }
    let action = match outputs.get("action") {
        Some(s) if s.len() == 1 => s[0],
        _ => return Err(bad("config.json: no 1-D output `action`".into())),
    };
    Ok(((*image).clone(), (*shape).clone(), state, action))
}

/// The side frames are resized to before the crop (antialiased, as torchvision's `Resize`
/// treats float tensors) and the crop's side, as LeRobot's `DiffusionConfig.__post_init__`
/// derives them: with `resize_shape`, the crop is `⌊side · crop_ratio⌋` when the ratio is below 1
/// and none at 1 (whatever `crop_shape` says); without it, `crop_shape`. Call after [`check`].
pub(crate) fn resize_and_crop(c: &LeRobotConfig) -> (Option<usize>, Option<usize>) {
    match c.resize_shape.as_deref() {
        Some(&[side, _]) => {
            let ratio = c.crop_ratio.unwrap_or(1.0);
            (Some(side), (ratio < 1.0).then_some((side as f64 * ratio) as usize))
        }
        _ => (None, c.crop_shape.map(|[h, _]| h)),
    }
}

/// Refuses settings this importer does not implement, naming the `config.json` field.
pub(crate) fn check(c: &LeRobotConfig, path: &Path) -> Result<(), ImportError> {
    let refuse = |field: &str, value: String, supported: &str| {
        Err(ImportError::Layout {
            path: path.into(),
            what: format!("config.json `{field}` is {value}; supported: {supported}"),
        })
    };
    if c.vision_backbone != "resnet18" {
        return refuse("vision_backbone", c.vision_backbone.clone(), "resnet18");
    }
    if c.use_separate_rgb_encoder_per_camera {
        return refuse("use_separate_rgb_encoder_per_camera", "true".into(), "false");
    }
    if let Some(r) = &c.resize_shape
        && !(r.len() == 2 && r[0] == r[1] && r[0] > 0)
    {
        return refuse("resize_shape", format!("{r:?}"), "a square [side, side] or none");
    }
    if let Some(q) = c.crop_ratio
        && !(q > 0.0 && q <= 1.0)
    {
        return refuse("crop_ratio", q.to_string(), "in (0, 1]");
    }
    if !c.use_film_scale_modulation {
        return refuse("use_film_scale_modulation", "false".into(), "true");
    }
    if c.n_groups != 8 {
        return refuse("n_groups", c.n_groups.to_string(), "8");
    }
    if c.noise_scheduler_type != "DDPM" && c.noise_scheduler_type != "DDIM" {
        return refuse("noise_scheduler_type", c.noise_scheduler_type.clone(), "DDPM or DDIM");
    }
    if c.beta_schedule != "squaredcos_cap_v2" {
        return refuse("beta_schedule", c.beta_schedule.clone(), "squaredcos_cap_v2");
    }
    if c.prediction_type != "epsilon" && c.prediction_type != "sample" {
        return refuse("prediction_type", c.prediction_type.clone(), "epsilon or sample");
    }
    if !c.clip_sample || c.clip_sample_range != 1.0 {
        return refuse(
            "clip_sample_range",
            format!("{} (clip_sample {})", c.clip_sample_range, c.clip_sample),
            "1.0 with clip_sample",
        );
    }
    if c.crop_shape.is_some_and(|[h, w]| h != w) {
        return refuse("crop_shape", format!("{:?}", c.crop_shape), "a square");
    }
    let modes: BTreeMap<String, String> = match (&c.normalization_mapping, &c.input_normalization_modes) {
        (Some(m), _) => m.clone(),
        (None, Some(i)) => {
            let mut m = BTreeMap::new();
            for (k, v) in i.iter().chain(c.output_normalization_modes.iter().flatten()) {
                let kind = if k.starts_with("observation.image") {
                    "VISUAL"
                } else if k == "action" {
                    "ACTION"
                } else {
                    "STATE"
                };
                m.insert(kind.to_string(), v.to_uppercase());
            }
            m
        }
        _ => BTreeMap::new(),
    };
    for (kind, want) in [("VISUAL", "MEAN_STD"), ("STATE", "MIN_MAX"), ("ACTION", "MIN_MAX")] {
        let got = modes.get(kind).map(String::as_str).unwrap_or("(absent)");
        if got != want {
            return refuse(&format!("normalization_mapping.{kind}"), got.into(), want);
        }
    }
    Ok(())
}
