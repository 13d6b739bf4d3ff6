//! `evalharness import` arguments: models trained by other code, converted once into
//! evalharness's own folders.

use std::path::PathBuf;

use clap::{Args, Subcommand, ValueEnum};

/// `evalharness import`.
#[derive(Debug, Subcommand)]
pub enum ImportCommand {
    /// A world model from another codebase's checkpoint, as an evalharness world-model
    /// folder (`config.json`, `ema.bpk`, `provenance.json`) that `rank`, `plan`, `wm eval`
    /// and `simulate --replay-imagined` take with `--world-model`.
    WorldModel(ImportWorldModelArgs),
    /// A judge of imagined frames from another codebase's files, as an evalharness judge
    /// folder that `rank --judge` takes.
    Judge(ImportJudgeArgs),
    /// A policy checkpoint from another codebase, as an evalharness checkpoint folder
    /// (`policy.json`, `model.bpk`) that `rank --policies`, `simulate --policy` and `plan`
    /// take.
    Policy(ImportPolicyArgs),
}

/// The formats `import policy` reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PolicyFormat {
    /// DriftWorld/GPC's Push-T diffusion policies (`ckpt-ep{N}.pth`:
    /// `torch.save({step, model, ema, optimizer, scheduler, cfg})`).
    Gpc,
    /// LeRobot's diffusion policies: a `pretrained_model/` folder (`config.json`,
    /// `model.safetensors`, and from LeRobot 0.4 the preprocessor's statistics).
    Lerobot,
    /// robomimic's diffusion policies (a `.pth` from its `save_model`: `model.{nets, ema}`,
    /// `config`, `shape_metadata`, statistics), for Lift or Can (`--scenario`).
    Robomimic,
}

/// Which copy of a policy checkpoint's weights to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PolicyWeights {
    /// What the codebase's own evaluation runs: GPC's `ema.shadow_params`; robomimic's
    /// `model.ema` when its config enables EMA, else `model.nets`.
    Ema,
    /// `model`, the weights before averaging.
    Model,
}

/// `evalharness import policy`.
#[derive(Debug, Args)]
pub struct ImportPolicyArgs {
    /// The checkpoint: a file (`ckpt-ep50.pth`) or, for LeRobot, the `pretrained_model` folder.
    pub file: PathBuf,
    /// The file's format.
    #[arg(long, value_enum)]
    pub format: PolicyFormat,
    /// The checkpoint folder to write (its name is the policy's name in every table).
    #[arg(long)]
    pub out: PathBuf,
    /// Which weights to import (GPC's files hold two copies; LeRobot's one).
    #[arg(long, value_enum, default_value = "ema")]
    pub weights: PolicyWeights,
    /// GPC's format: the normalisation statistics, a JSON file `{"agent_pos": {"min": [..],
    /// "max": [..]}, "action": {"min": [..], "max": [..]}}` (GPC's files carry none; default: the
    /// ranges GPC's Push-T evaluation script uses).
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// The scenario the policy is for (robomimic: its robot-state keys are matched to what
    /// the scenario gives before anything is written; default: the checkpoint's
    /// `env_metadata.env_name`, Lift → lift, PickPlaceCan → can).
    #[arg(long)]
    pub scenario: Option<String>,
    /// Frames' side in pixels the policy reads.
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u16).range(32..=1024))]
    pub image_size: u16,
    /// Replace `--out` if it exists (only once the new folder is complete).
    #[arg(long)]
    pub force: bool,
}

/// The formats `import judge` reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum JudgeFormat {
    /// GPC's Push-T reward predictors: two ResNet-18 `state_dict` files (`--xy`, `--angle`)
    /// that read the T block's pose; the episode's goal turns it into the exact coverage.
    GpcRewardPredictor,
}

/// `evalharness import judge`.
#[derive(Debug, Args)]
pub struct ImportJudgeArgs {
    /// The files' format.
    #[arg(long, value_enum)]
    pub format: JudgeFormat,
    /// The position predictor (`reward_predictor_xy.pth`).
    #[arg(long)]
    pub xy: PathBuf,
    /// The orientation predictor (`reward_predictor_angle.pth`).
    #[arg(long)]
    pub angle: PathBuf,
    /// The judge folder to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Frames' side in pixels the judge reads.
    #[arg(long, default_value_t = 96, value_parser = clap::value_parser!(u16).range(32..=1024))]
    pub image_size: u16,
    /// Replace `--out` if it exists (only once the new folder is complete).
    #[arg(long)]
    pub force: bool,
}

/// The formats `import world-model` reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum WorldModelFormat {
    /// The official DriftWorld code's `torch.save({step, model, optimizer, scheduler})`.
    Driftworld,
}

/// Which copy of a checkpoint's weights to import.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ImportWeights {
    /// The EMA copy (`model.ema_model.*`), what the official sampler uses.
    Ema,
    /// The trained weights before averaging (`model.inner_model.*`).
    Inner,
}

/// What the file cannot tell: future frames per pass, frame size, head width, action scale.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ImportPreset {
    /// Push-T: 4 future frames, 96² frames, actions in world units 0..511.
    Pusht,
    /// robomimic Lift: 2 future frames, 96² frames, 7-D actions in [-1, 1].
    Lift,
    /// robomimic Can: as Lift.
    Can,
}

/// `evalharness import world-model`.
#[derive(Debug, Args)]
pub struct ImportWorldModelArgs {
    /// The checkpoint (`ckpt-step*.pth`).
    pub file: PathBuf,
    /// The file's format.
    #[arg(long, value_enum)]
    pub format: WorldModelFormat,
    /// The world-model folder to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Which weights to import.
    #[arg(long, value_enum, default_value = "ema")]
    pub weights: ImportWeights,
    /// The official configuration the checkpoint was trained with.
    #[arg(long, value_enum, default_value = "pusht")]
    pub preset: ImportPreset,
    /// Frames' side in pixels, when not the preset's 96 (a reduced model).
    #[arg(long, value_parser = clap::value_parser!(u16).range(8..=1024))]
    pub image_size: Option<u16>,
    /// Replace `--out` if it exists (only once the new folder is complete).
    #[arg(long)]
    pub force: bool,
}
