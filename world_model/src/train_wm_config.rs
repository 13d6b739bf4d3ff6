//! A world-model run's training settings (`WmTrainConfig`) and its `config.json`
//! (`WmConfigs`), apart from the loop (`train_wm`) and its parts (`train_wm_parts`) that both
//! read them.

use serde::{Deserialize, Serialize};

use crate::drift_step::FieldKind;
use crate::model::Objective;
use crate::motion::MotionWeighting;
use crate::train_ae::Configs;

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WmTrainConfig {
    /// Optimizer steps in total.
    pub steps: u64,
    /// Contexts per step B.
    pub contexts: usize,
    /// Generated samples per context N (drifting; 1 for the baselines).
    pub samples: usize,
    /// Peak learning rate.
    pub lr: f64,
    /// Warm-up steps.
    pub warmup: u64,
    /// Seed of the initial weights, windows and noise.
    pub seed: u64,
    /// EMA decay per step.
    pub ema_decay: f64,
    /// Global gradient-norm clip.
    pub clip_norm: f64,
    /// Drift temperatures.
    pub temperatures: Vec<f32>,
    /// Held-out evaluation every this many steps.
    pub eval_every: u64,
    /// Held-out windows in that evaluation.
    pub eval_windows: usize,
    /// Checkpoint every this many steps.
    pub checkpoint_every: u64,
    /// How generated latents are cut into drift problems (runs saved before this
    /// option existed used whole frames).
    #[serde(default)]
    pub field: FieldKind,
    /// A world-model folder whose EMA weights initialise this run (same U-Net).
    #[serde(default)]
    pub init_from: Option<std::path::PathBuf>,
    /// Motion weighting of the per-token losses (spec §4; needs [`FieldKind::Token`]).
    #[serde(default)]
    pub motion: Option<MotionWeighting>,
    /// Chunks per training rollout (drifting): 1 = phase 1 (true history); L > 1 =
    /// self-forcing over L chunks (spec §7).
    #[serde(default = "one")]
    pub chunks: usize,
    /// Context-noise augmentation: each training history row gets Gaussian noise of
    /// a level drawn from U[0, this] (normalised latent units; 0 = off; not in the paper).
    #[serde(default)]
    pub context_noise: f32,
}

fn one() -> usize {
    1
}

impl WmTrainConfig {
    /// Defaults sized for a 2-core CPU: 4 contexts x 8 samples for drifting,
    /// 32 contexts x 1 for the baselines (the same number of clips per step).
    pub fn for_objective(objective: Objective) -> Self {
        let (contexts, samples) = if objective == Objective::Drifting { (4, 8) } else { (32, 1) };
        Self {
            steps: 6000,
            contexts,
            samples,
            lr: 2e-4,
            warmup: 500,
            seed: 1,
            ema_decay: 0.999,
            clip_norm: 2.0,
            temperatures: crate::drift::PUSHT_TEMPERATURES.to_vec(),
            eval_every: 250,
            eval_windows: 32,
            checkpoint_every: 50,
            field: FieldKind::Frame,
            init_from: None,
            motion: None,
            chunks: 1,
            context_noise: 0.0,
        }
    }
}

/// A world-model run's `config.json`: the model's configuration and the training's.
pub type WmConfigs = Configs<crate::model::WorldModelConfig, WmTrainConfig>;
