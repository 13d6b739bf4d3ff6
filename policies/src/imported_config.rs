//! The settings of an imported diffusion policy ([`crate::imported_policy`]): the few in which
//! GPC's, LeRobot's and robomimic's networks of one family differ (the frame features' pool,
//! the sampler, what the network predicts, the normalisation of its inputs), as `policy.json`
//! stores them.

use serde::{Deserialize, Serialize};

use crate::net::NetConfig;
use crate::resnet_gn::BackboneNorm;

/// How the ResNet's last map becomes a frame's features.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum Pool {
    /// Global average pool (GPC: 8 × base features).
    #[default]
    Average,
    /// A spatial softmax over `keypoints` keypoints, a linear layer and a ReLU (LeRobot:
    /// 2 × keypoints features; robomimic: `features` of them).
    SpatialSoftmax {
        /// Keypoints K.
        keypoints: usize,
        /// The linear layer's outputs (absent: 2K, as LeRobot has it).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        features: Option<usize>,
    },
}

impl Pool {
    fn is_average(&self) -> bool {
        *self == Self::Average
    }
}

/// How an imported policy denoises its action sequence.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampler {
    /// diffusers' `DDPMScheduler` (stochastic steps).
    #[default]
    Ddpm,
    /// diffusers' `DDIMScheduler` with η = 0 (deterministic steps).
    Ddim,
}

impl Sampler {
    fn is_ddpm(&self) -> bool {
        *self == Self::Ddpm
    }
}

/// What the noise predictor's output is (diffusers' `prediction_type`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Prediction {
    /// The noise ε (`epsilon`).
    #[default]
    Epsilon,
    /// The clean sample x₀ (`sample`): the noise is derived from it as diffusers derives it,
    /// `(x − √ᾱ·x₀) / √(1 − ᾱ)`, before x₀ is clipped.
    Sample,
}

impl Prediction {
    fn is_epsilon(&self) -> bool {
        *self == Self::Epsilon
    }

    /// The noise the samplers step with, from the network's `out` for `x` at ᾱ = `a`.
    pub fn noise(self, x: &[f32], out: Vec<f32>, a: f64) -> Vec<f32> {
        match self {
            Self::Epsilon => out,
            Self::Sample => {
                let (sa, s1a) = (a.sqrt(), (1.0 - a).sqrt());
                x.iter().zip(out).map(|(&x, x0)| ((f64::from(x) - sa * f64::from(x0)) / s1a) as f32).collect()
            }
        }
    }
}

/// Per-channel image normalisation, `(x − mean) / (std + 1e-8)` of frames in [0, 1].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeanStd {
    /// Per-channel mean.
    pub mean: [f32; 3],
    /// Per-channel standard deviation.
    pub std: [f32; 3],
}

/// An imported policy's configuration (`policy.json` "config").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportedConfig {
    /// The ResNet's base width (64 in the released policies).
    pub resnet_base: usize,
    /// How the ResNet normalises (absent: GroupNorm, as every policy imported before LeRobot's
    /// BatchNorm backbones was).
    #[serde(default, skip_serializing_if = "BackboneNorm::is_group")]
    pub backbone_norm: BackboneNorm,
    /// How the ResNet's map becomes features (absent: GPC's average pool).
    #[serde(default, skip_serializing_if = "Pool::is_average")]
    pub pool: Pool,
    /// The side frames are resized to (bilinear, PyTorch's `align_corners=False` without
    /// antialiasing) before the crop: the size the policy was trained on where the scenario
    /// renders another (robomimic's 84 against evalharness's 96; absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input_size: Option<usize>,
    /// Whether that resize is antialiased, as torchvision's `Resize` treats float tensors
    /// (LeRobot's `resize_shape`), rather than plain bilinear (robomimic's; absent: plain).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub antialias: bool,
    /// The side of the centre crop of each frame before the ResNet (absent: none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<usize>,
    /// Image normalisation (absent: frames in [0, 1] as they are).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_norm: Option<MeanStd>,
    /// Whether each frame's conditioning starts with the position (LeRobot) rather than the
    /// features (GPC).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub position_first: bool,
    /// The robot-state keys read with each frame in place of the task's proprioception, in
    /// order (robomimic's `robot0_eef_pos`, …; the task gives them as
    /// [`harness::task::ObservationSpec::robot`]; absent: the proprioception).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub robot_keys: Vec<String>,
    /// Denoising steps at sampling, spaced evenly from the last (absent: every training step).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub inference_steps: Option<usize>,
    /// The sampler (absent: DDPM, as every policy imported before DDIM was).
    #[serde(default, skip_serializing_if = "Sampler::is_ddpm")]
    pub sampler: Sampler,
    /// What the U-Net predicts (absent: the noise).
    #[serde(default, skip_serializing_if = "Prediction::is_epsilon")]
    pub prediction: Prediction,
    /// The U-Net's sizes (`feature_dim` as the pool gives; `encoder_width` unused).
    pub net: NetConfig,
    /// Predicted actions per decision.
    pub horizon: usize,
    /// Executed actions per decision.
    pub action_horizon: usize,
    /// DDPM steps (training and sampling).
    pub train_steps: usize,
}

impl ImportedConfig {
    /// The most actions a decision can execute (from the current observation's step on).
    pub fn max_action_horizon(&self) -> usize {
        (self.horizon + 1).saturating_sub(self.net.obs_horizon)
    }

    /// The denoising steps, noisiest first: `j · ⌊T / n⌋` for j = n − 1 … 0 (diffusers'
    /// "leading" spacing; every step when `inference_steps` is absent).
    pub fn timesteps(&self) -> Vec<usize> {
        let t = self.train_steps;
        let n = self.inference_steps.unwrap_or(t).clamp(1, t.max(1));
        (0..n).rev().map(|j| j * (t / n)).collect()
    }
}
