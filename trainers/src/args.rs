//! `evalharness train ...` arguments: the four trainers and the session flags
//! they share.

use std::path::PathBuf;

use clap::{Args, Subcommand};

/// `evalharness train ...`.
#[derive(Debug, Subcommand)]
pub enum TrainCommand {
    /// The frame autoencoder whose latent space the world model works in.
    Autoencoder(TrainAutoencoderArgs),
    /// The DriftWorld U-Net (or a baseline) on the autoencoder's latents.
    WorldModel(TrainWorldModelArgs),
    /// A diffusion policy; checkpoints every few epochs form a graded policy set.
    Policy(TrainPolicyArgs),
    /// A learned judge of imagined frames: a small CNN trained on simulator frames
    /// labelled with the exact score (`rank --judge`).
    Judge(TrainJudgeArgs),
    /// Adapts a task's models to another rendering of its frames: each frame encoder (the
    /// policies' and the autoencoder's) distilled to read the new frames as it read the old,
    /// on the same episodes rendered both ways; everything else copied.
    Adapt(TrainAdaptArgs),
}

/// What a judge learns to read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum JudgeLabelArg {
    /// Push-T's goal coverage (`data/coverage`); success above 0.95.
    Coverage,
    /// robomimic's success (`data/success`); success above 0.5.
    Success,
}

/// `evalharness train judge`.
#[derive(Debug, Args)]
pub struct TrainJudgeArgs {
    /// Dataset of simulator frames with a per-step label array (zarr replay buffer).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: `judge.json`, `model.bpk`, `log.jsonl`, and the run's resumable state
    /// in `.train/`.
    #[arg(long)]
    pub out: PathBuf,
    /// The label to learn (default: coverage if the dataset has it, else success).
    #[arg(long, value_enum)]
    pub label: Option<JudgeLabelArg>,
    /// Optimiser steps.
    #[arg(long, default_value_t = 2000)]
    pub steps: u64,
    /// Frames per step.
    #[arg(long, default_value_t = 64, value_parser = runner::bounds::batch())]
    pub batch: usize,
    /// Peak learning rate (after a 100-step warm-up).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Frame-encoder width.
    #[arg(long, default_value_t = 16, value_parser = runner::bounds::width())]
    pub encoder_width: usize,
    /// Feature size before the one-logit head.
    #[arg(long, default_value_t = 64, value_parser = runner::bounds::width())]
    pub feature_dim: usize,
    /// Use at most this many episodes (the first ones).
    #[arg(long)]
    pub episodes: Option<usize>,
    /// Judged frames in a row that must show success before an imagined episode counts
    /// it (`judge.json`'s `persist_frames`; `read-judge --out` chooses it on data).
    #[arg(long, default_value_t = 1)]
    pub persist: usize,
    /// Draw batches uniformly instead of half from frames above the threshold.
    #[arg(long)]
    pub no_balance: bool,
    /// Augment with the 8 symmetries of the square world (right for Push-T's
    /// top-down view, wrong for a perspective camera).
    #[arg(long)]
    pub symmetries: bool,
    /// Evaluate on the held-out episodes every this many steps.
    #[arg(long, default_value_t = 250)]
    pub eval_every: u64,
    /// Seed of the weights and the frame order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Session control: `--max-minutes` ends a session with a checkpoint, the judge trained
    /// so far evaluated and written (`judge.json`'s `steps`); `--resume` continues it.
    #[command(flatten)]
    pub session: SessionArgs,
}

/// `evalharness train policy`.
#[derive(Debug, Args)]
pub struct TrainPolicyArgs {
    /// Demonstration dataset (zarr replay buffer).
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder: `epoch-NNNN/` checkpoints and the resumable `.train/` state.
    #[arg(long)]
    pub out: PathBuf,
    /// Epochs (passes over the demonstration samples); with `--resume`, the new total.
    #[arg(long)]
    pub epochs: Option<u64>,
    /// Save a policy checkpoint every this many epochs.
    #[arg(long, default_value_t = 1)]
    pub save_every: u64,
    /// Use only episodes of this behaviour (as recorded by `collect`); "all" for every episode.
    #[arg(long, default_value = "expert")]
    pub behaviour: String,
    /// Use at most this many episodes (after the behaviour filter).
    #[arg(long)]
    pub episodes: Option<usize>,
    /// Samples per step.
    #[arg(long, default_value_t = 64, value_parser = runner::bounds::batch())]
    pub batch: usize,
    /// Learning rate (after a 200-step warm-up).
    #[arg(long, default_value_t = 3e-4)]
    pub lr: f64,
    /// Frame-encoder width.
    #[arg(long, default_value_t = 16, value_parser = runner::bounds::width())]
    pub encoder_width: usize,
    /// U-Net channels per level, comma-separated.
    #[arg(long, default_value = "32,64,128", value_delimiter = ',')]
    pub down_dims: Vec<usize>,
    /// DDIM steps at inference.
    #[arg(long, default_value_t = 10)]
    pub inference_steps: usize,
    /// Pre-train the frame encoder this many steps to regress the agent and block
    /// poses, then freeze it and train the U-Net on cached features (fast on a CPU);
    /// 0 trains end to end as Chi et al. do.
    #[arg(long, default_value_t = 3000)]
    pub encoder_steps: u64,
    /// Peak learning rate of the encoder's pose pre-training.
    #[arg(long, default_value_t = 1e-3)]
    pub encoder_lr: f64,
    /// Start from the pose-pre-trained encoder of another run's folder (its
    /// `.train/encoder*`), e.g. to train several U-Nets on one encoder.
    #[arg(long)]
    pub encoder_from: Option<PathBuf>,
    /// Fine-tune a diffusion-policy checkpoint folder (e.g. on more demonstrations):
    /// start from its weights, network config, action horizon and normalisation; its
    /// encoder stays frozen and the U-Net trains on cached features. Epochs count
    /// from 1 again; each checkpoint's provenance nests the starting one's.
    #[arg(long, conflicts_with_all = ["encoder_from", "encoder_steps"])]
    pub init_from: Option<PathBuf>,
    /// Decay of the weights' moving average that checkpoints are saved from (0: raw
    /// weights); 0.999 for a new run. With `--resume`, switches the EMA on (from the
    /// current weights) or changes its decay.
    #[arg(long)]
    pub ema: Option<f64>,
    /// Seed of the weights, sample order and noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Session control.
    #[command(flatten)]
    pub session: SessionArgs,
}

/// The world model's training objective.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ObjectiveArg {
    /// DriftWorld's drifting loss (one pass per chunk).
    Drifting,
    /// One-step MSE regression baseline.
    Mse,
    /// Multi-step diffusion baseline (DDIM sampling with `--sample-steps`).
    Diffusion,
}

/// The diffusion baseline's parameterisation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PredictionArg {
    /// v = √ᾱ·ε − √(1−ᾱ)·x0.
    V,
    /// The clean frames.
    X0,
}

/// Which space the world model works in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum WmConfigArg {
    /// 12x12x8 latents of a trained frame autoencoder (the CPU default; needs
    /// `--autoencoder`).
    PushtLatent,
    /// The paper's pixel-space Push-T model: 96x96 RGB, 96 base channels, 8,375,201
    /// parameters (a GPU job: build with `--features cuda`, run with
    /// `EVALHARNESS_DEVICE=cuda`).
    PushtPixel,
}

/// `evalharness train world-model`.
#[derive(Debug, Args)]
pub struct TrainWorldModelArgs {
    /// Training dataset (zarr replay buffer); every 10th episode is held out.
    #[arg(long)]
    pub data: PathBuf,
    /// Model family: autoencoder latents or pixels. With `--resume` the saved config
    /// holds; model and loss flags that contradict it are refused.
    #[arg(long, value_enum, default_value_t = WmConfigArg::PushtLatent)]
    pub config: WmConfigArg,
    /// Trained autoencoder folder (from `train autoencoder`); required by
    /// `--config pusht-latent`, refused by `--config pusht-pixel`.
    #[arg(long)]
    pub autoencoder: Option<PathBuf>,
    /// Training objective.
    #[arg(long, value_enum, default_value_t = ObjectiveArg::Drifting)]
    pub objective: ObjectiveArg,
    /// Output folder (checkpoints, logs, provenance).
    #[arg(long)]
    pub out: PathBuf,
    /// Optimizer steps in total (default 6000); with `--resume`, extends or shortens the run.
    #[arg(long)]
    pub steps: Option<u64>,
    /// U-Net base channels (default 32 in latent space, the paper's 96 in pixel space).
    #[arg(long)]
    pub base_channels: Option<usize>,
    /// Contexts per step (default 4 for drifting, 32 for the baselines).
    #[arg(long)]
    pub contexts: Option<usize>,
    /// Generated samples per context (drifting negatives; default 8).
    #[arg(long)]
    pub samples: Option<usize>,
    /// Drift problems (drifting): one per whole frame, or one per latent cell
    /// (DriftWorld's latent family).
    #[arg(long, value_enum, default_value_t = FieldArg::Frame)]
    pub field: FieldArg,
    /// Learning-rate warm-up steps (linear from 1e-6); a warm start (`--init-from`)
    /// needs fewer.
    #[arg(long, default_value_t = 500)]
    pub warmup: u64,
    /// Self-forcing (spec §7, drifting): train on rollouts of L chunks in which each
    /// sample's history is its own detached predictions; 1 = true history only.
    #[arg(long, default_value_t = 1)]
    pub self_forcing: usize,
    /// Context-noise augmentation (not in the paper): add Gaussian noise of a level
    /// drawn from U[0, SIGMA] to each training history (normalised latent units), so
    /// the model learns to predict from the imperfect histories of its own rollouts.
    #[arg(long, default_value_t = 0.0, value_name = "SIGMA")]
    pub context_noise: f32,
    /// Weight each latent cell's loss by how much it moves (spec §4; with `--field token`).
    #[arg(long)]
    pub motion_weighting: bool,
    /// Also give the U-Net each future frame's action as a Gaussian map at its
    /// position (an input channel; not in the paper). With `--init-from` a model
    /// without maps, the new channel starts at zero weight.
    #[arg(long)]
    pub action_maps: bool,
    /// Also give the U-Net the episode's first frame (the anchor) with every chunk (C
    /// input channels; not in the paper): a real view of the static scene and of the
    /// block's shape that a long closed-loop rollout cannot erode. With `--init-from`
    /// a model without it, the new channels start at zero weight.
    #[arg(long)]
    pub anchor: bool,
    /// Train on the frames re-rendered without the goal T (from `data/state`; not in
    /// the paper). The goal is static and known from the initial state, so `rank` and
    /// `wm eval` draw it onto the generated frames instead of the model predicting
    /// it — and the model cannot learn the expert data's "blocks go to the goal"
    /// prior from seeing where the goal is. Needs a dataset collected by evalharness.
    #[arg(long)]
    pub goal_free: bool,
    /// Action accentuation (spec §3; drifting only): each context draws a strength α
    /// (log-uniform on [1, 4], 1 with probability 0.1), fed to the U-Net, and the true
    /// current frame joins the negatives with weight (α − 1)(N − 1). With
    /// `--init-from` a model without it, the α MLP starts with zero output.
    #[arg(long)]
    pub accentuation: bool,
    /// The α an accentuated model uses at inference (written to its config; >= 1;
    /// default 2.5, the authors' RT-1 setting).
    #[arg(long, value_name = "ALPHA")]
    pub alpha: Option<f32>,
    /// Start from another world-model run's EMA weights (same U-Net and autoencoder;
    /// its latent statistics are reused).
    #[arg(long)]
    pub init_from: Option<PathBuf>,
    /// Peak learning rate (after a 500-step warm-up).
    #[arg(long, default_value_t = 2e-4)]
    pub lr: f64,
    /// Decay of the weights' moving average that sampling uses (default 0.999). With
    /// `--resume`, changes it for the rest of the run (recorded in `config.json`),
    /// e.g. 0.99 so a short warm-started fine-tune's EMA catches up with its weights.
    #[arg(long)]
    pub ema_decay: Option<f64>,
    /// DDIM steps per generated chunk (diffusion).
    #[arg(long, default_value_t = 10)]
    pub sample_steps: usize,
    /// What the diffusion U-Net predicts: v, or the clean frames x0 (which lets
    /// `--init-from` start it from a drifting or MSE model: its timestep embedding is
    /// added with zero output).
    #[arg(long, value_enum, default_value_t = PredictionArg::V)]
    pub prediction: PredictionArg,
    /// Seed of the weights, windows and noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Held-out evaluation interval (steps).
    #[arg(long, default_value_t = 250)]
    pub eval_every: u64,
    /// Held-out windows in each evaluation (one chunk each, fixed noise).
    #[arg(long, default_value_t = 32)]
    pub eval_windows: usize,
    /// Checkpoint interval (steps).
    #[arg(long, default_value_t = 50)]
    pub checkpoint_every: u64,
    /// Session control.
    #[command(flatten)]
    pub session: SessionArgs,
}

/// `evalharness train autoencoder`.
#[derive(Debug, Args)]
pub struct TrainAutoencoderArgs {
    /// Training dataset (zarr replay buffer); every 10th episode is held out.
    #[arg(long)]
    pub data: PathBuf,
    /// Output folder (checkpoints, logs, provenance).
    #[arg(long)]
    pub out: PathBuf,
    /// Optimizer steps in total (default 4000); with `--resume`, extends or shortens the run.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Frames per step.
    #[arg(long, default_value_t = 16, value_parser = runner::bounds::batch())]
    pub batch: usize,
    /// Peak learning rate (after a 200-step warm-up).
    #[arg(long, default_value_t = 1e-3)]
    pub lr: f64,
    /// Seed of the weights and batches.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Held-out evaluation interval (steps).
    #[arg(long, default_value_t = 250)]
    pub eval_every: u64,
    /// Checkpoint interval (steps).
    #[arg(long, default_value_t = 100)]
    pub checkpoint_every: u64,
    /// Train only a decoder, on the fixed latents of this autoencoder's encoder (its
    /// weights are copied and never change), so that world models trained on those
    /// latents can use the new decoder (`wm export --autoencoder`).
    #[arg(long, value_name = "AUTOENCODER")]
    pub encoder_from: Option<PathBuf>,
    /// The decoder's channels at 96, 48, 24 and 12 pixels (default: the encoder's,
    /// 16,32,64,64). A narrower decoder is cheaper per decoded frame in `rank`.
    #[arg(long, value_delimiter = ',')]
    pub decoder_channels: Option<Vec<usize>>,
    /// Session control.
    #[command(flatten)]
    pub session: SessionArgs,
}

/// `evalharness train adapt`.
#[derive(Debug, Args)]
pub struct TrainAdaptArgs {
    /// A task's model folder, laid out as `checkpoints/<task>`: `policies/` (diffusion
    /// checkpoints), `autoencoder/`, and optionally `world_model/`, `judge/`, `rank.toml`.
    #[arg(long)]
    pub models: PathBuf,
    /// Episodes rendered as the models were trained (`collect` with the old rendering).
    #[arg(long)]
    pub from: PathBuf,
    /// The same episodes rendered the new way (`collect` with the same seeds, behaviours and
    /// step limit, and the new scenario file's `[visual]`).
    #[arg(long)]
    pub to: PathBuf,
    /// Output folder: the adapted model folder, in the same layout.
    #[arg(long)]
    pub out: PathBuf,
    /// Distillation steps of each distinct policy frame encoder (the default is what adapted
    /// Lift's models to cheap frames, BENCHMARKS.md, 2026-12-03).
    #[arg(long, default_value_t = 1500)]
    pub steps: u64,
    /// Distillation steps of the autoencoder's encoder.
    #[arg(long, default_value_t = 600)]
    pub ae_steps: u64,
    /// Frame pairs per step.
    #[arg(long, default_value_t = 32, value_parser = runner::bounds::batch())]
    pub batch: usize,
    /// Peak learning rate (AdamW), decayed to 0 along a half cosine.
    #[arg(long, default_value_t = 2e-4)]
    pub lr: f64,
    /// Seed of the frame order.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Replace an existing `--out` (once the new folder is complete).
    #[arg(long)]
    pub force: bool,
}

/// Session control shared by the trainers.
#[derive(Debug, Args)]
pub struct SessionArgs {
    /// Stop (with a checkpoint) after this many minutes; `--resume` continues.
    #[arg(long)]
    pub max_minutes: Option<f64>,
    /// Continue the run in `--out` from its last checkpoint (its config wins).
    #[arg(long)]
    pub resume: bool,
    /// Replace an existing `--out` (without `--resume`).
    #[arg(long)]
    pub force: bool,
}

/// `--field` of `train world-model`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum FieldArg {
    /// One drift problem per future frame.
    Frame,
    /// One drift problem per latent cell of each future frame.
    Token,
}
