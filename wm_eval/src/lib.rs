//! `evalharness wm eval`: world models' rollouts compared with held-out episodes of a
//! dataset, written as `eval.json` (typed: [`report::EvalFile`]) and `filmstrip.png`.
//!
//! What it measures, per model: 64-frame videos (4 real frames of context, 60
//! generated from the recorded actions) and whole episodes, by MSE, PSNR and SSIM with
//! intervals over episodes ([`run`]); references that bound them (the last context
//! frame repeated, and each latent model's autoencoder rendering the real future);
//! on Push-T datasets the open-loop score the frame scorer reads from the generated
//! frames against the real ones ([`score`]) and the SSIM by how far the block moves
//! ([`motion`]); with a learned judge, the open-loop success by behaviour
//! ([`success`]). Which videos: [`windows`].
//!
//! The command's arguments are [`Options`] (clap parses them directly), so the binary
//! only prints the lines [`run()`] hands it.

use std::path::PathBuf;

use clap::Args;

mod error;
pub mod motion;
pub mod report;
pub mod run;
pub mod score;
pub mod success;
pub mod windows;

pub use error::WmEvalError;
pub use run::run;
pub use windows::Windows;

/// `evalharness wm eval`'s arguments.
#[derive(Debug, Clone, Args)]
pub struct Options {
    /// World-model folders to compare (repeat the flag).
    #[arg(long = "world-model", required = true)]
    pub world_models: Vec<PathBuf>,
    /// Dataset; only held-out episodes (index % 10 == 9) are used, unless `--all-episodes`.
    #[arg(long)]
    pub data: PathBuf,
    /// Use every episode, not only the held-out tenth: for a dataset no compared model
    /// was trained on (e.g. `collect --policy` rollouts kept for diagnosis).
    #[arg(long)]
    pub all_episodes: bool,
    /// 64-frame videos to roll out (4 real + 60 generated), one per held-out episode
    /// with `--windows first`.
    #[arg(long, default_value_t = 20)]
    pub episodes: usize,
    /// Where the 64-frame videos start: `first` = each episode's opening (approach and
    /// first contact, the hardest stretch); `random` = windows drawn uniformly over
    /// every position of the held-out episodes from `--seed` (the authors' protocol,
    /// the one paper numbers are measured on).
    #[arg(long, value_enum, default_value_t = Windows::First)]
    pub windows: Windows,
    /// Roll out the 64-frame video whose context starts at this dataset step instead
    /// (repeat the flag; e.g. a `start` from `eval.json`'s `per_video`, to see one
    /// failure's filmstrip). Overrides `--windows` and `--episodes`.
    #[arg(long = "start")]
    pub starts: Vec<usize>,
    /// Held-out episodes rolled out from start to end.
    #[arg(long, default_value_t = 4)]
    pub full_episodes: usize,
    /// Videos generated together.
    #[arg(long, default_value_t = 20, value_parser = clap::builder::RangedU64ValueParser::<usize>::new().range(1..=1000))]
    pub batch: usize,
    /// Seed of the generator noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder (eval.json, filmstrip.png).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
    /// Action-accentuation strength α for accentuated models (default: each model's
    /// configured α).
    #[arg(long)]
    pub alpha: Option<f32>,
    /// The sampling-noise scale (temperature, in [0, 1]) of every compared model, as `rank
    /// --noise-scale` [default: each model's, else 1].
    #[arg(long, value_name = "T")]
    pub noise_scale: Option<f32>,
    /// A learned judge (from `train judge`): read the whole-episode videos for success
    /// as `rank` reads imagined episodes, with the recorded actions replayed and no
    /// policy in the loop, grouped by the dataset's behaviour (on `collect --policy`
    /// rollouts, the checkpoint), against the dataset's exact success.
    #[arg(long)]
    pub judge: Option<PathBuf>,
}
