//! What a policy training run is told and what it reports: the training hyper-parameters,
//! the configs saved with a run (and compared on `--resume`), a session's flags, its
//! progress reports and its outcome. The loop is `train`, its parts `train_parts`.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use crate::diffusion::{DiffusionConfig, Normalisation};
use crate::provenance::PolicyProvenance;

/// Training hyper-parameters.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyTrainConfig {
    /// Epochs in total.
    pub epochs: u64,
    /// Save a policy checkpoint every this many epochs (and after the last).
    pub save_every: u64,
    /// Samples per step.
    pub batch: usize,
    /// Learning rate after warm-up (AdamW β = (0.95, 0.999)); constant, so a run can be
    /// extended with more epochs without changing what was already trained.
    pub lr: f64,
    /// Linear warm-up steps.
    pub warmup: u64,
    /// AdamW weight decay.
    pub weight_decay: f64,
    /// Seed of the weights, sample order and noise.
    pub seed: u64,
    /// Save the training state every this many steps.
    pub checkpoint_every: u64,
    /// Pose pre-training steps of the frame encoder ([`crate::pretrain`]). 0 trains
    /// encoder and U-Net end to end (Chi et al.); more pre-trains the encoder, freezes
    /// it and trains the U-Net alone on cached features.
    #[serde(default)]
    pub encoder_steps: u64,
    /// Peak learning rate of the pose pre-training.
    #[serde(default = "default_encoder_lr")]
    pub encoder_lr: f64,
    /// Decay of the exponential moving average of the weights that checkpoints are
    /// saved from (Chi et al. sample from EMA weights); 0 saves the raw weights. The
    /// effective decay warms up as `min(ema, (1 + k) / (10 + k))` after k updates.
    #[serde(default)]
    pub ema: f64,
    /// A diffusion-policy checkpoint folder the run starts from instead of fresh
    /// weights (fine-tuning, e.g. on more demonstrations). Its encoder stays frozen
    /// (the U-Net trains on cached features) and the run must use its network config.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub init_from: Option<PathBuf>,
}

fn default_encoder_lr() -> f64 {
    1e-3
}

/// How to run a session.
#[derive(Clone, Copy, Debug, Default)]
pub struct PolicyRun {
    /// Continue from `.train/`.
    pub resume: bool,
    /// When resuming, train to this many epochs in total instead of the saved number.
    pub epochs: Option<u64>,
    /// Stop (with a saved state) after this many minutes.
    pub max_minutes: Option<f64>,
    /// When resuming, use this EMA decay from now on (an EMA started mid-run begins
    /// at the current weights).
    pub ema: Option<f64>,
}

/// What a training run is doing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Pose pre-training of the frame encoder.
    Encoder,
    /// Training the policy (the U-Net, and the encoder when end to end).
    Policy,
}

/// A progress report.
#[derive(Clone, Debug)]
pub struct PolicyProgress {
    /// The phase `step` and `total` count.
    pub phase: Phase,
    /// Steps done / in total.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Current epoch (1-based while running).
    pub epoch: u64,
    /// Last batch loss.
    pub loss: f64,
}

/// Saved configs of a run.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunConfigs {
    /// The policy.
    pub policy: DiffusionConfig,
    /// Training.
    pub train: PolicyTrainConfig,
    /// Data normalisation.
    pub normalisation: Normalisation,
    /// How the run was made (data, command), copied into every checkpoint.
    pub provenance: PolicyProvenance,
    /// The task of the demonstrations, recorded in every checkpoint's `policy.json`.
    #[serde(default)]
    pub task: Option<String>,
}

/// What a session ended with.
#[derive(Clone, Debug)]
pub struct PolicyOutcome {
    /// Steps done.
    pub step: u64,
    /// Steps in total.
    pub total: u64,
    /// Checkpoints written in this session.
    pub saved: Vec<PathBuf>,
    /// Mean loss of the last 50 steps.
    pub loss: f64,
    /// Training seconds over all sessions, as the state file records them.
    pub elapsed_s: f64,
}
