//! Errors of the world model, each naming the file, step or field at fault.

use std::path::PathBuf;

/// What can go wrong while loading data or checkpoints, or training.
#[derive(Debug, thiserror::Error)]
pub enum WorldModelError {
    /// A dataset that cannot be used.
    #[error("dataset {path}: {message}")]
    Data {
        /// The dataset.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A checkpoint that cannot be read or does not match its config.
    #[error("checkpoint {path}: {message}")]
    Checkpoint {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A loss or output that became NaN or infinite.
    #[error("non-finite {what} at training step {step} (output {path})")]
    NonFinite {
        /// Which quantity.
        what: String,
        /// The step.
        step: u64,
        /// The run's output folder.
        path: PathBuf,
    },
}

/// A run file (a log line, a state file) that cannot be read or written, as the trainers
/// report any file of their checkpoint.
impl From<harness::runfile::RunFileError> for WorldModelError {
    fn from(e: harness::runfile::RunFileError) -> Self {
        Self::Checkpoint { path: e.path, message: e.message }
    }
}

/// A setting a world model cannot take: a U-Net configuration burn would panic on, an
/// inference option the model has no input for or a value out of its range, actions of
/// another width.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SettingError {
    /// A size of the U-Net's configuration that is zero.
    #[error("{name} must be at least 1")]
    Zero {
        /// The setting's name in the config.
        name: &'static str,
    },
    /// The U-Net's channel multipliers.
    #[error("channel_mult {mult:?} needs one multiplier of at least 1 per level")]
    ChannelMult {
        /// The multipliers given.
        mult: Vec<usize>,
    },
    /// A level's channels that GroupNorm cannot split into its groups.
    #[error(
        "model_channels {base} x channel_mult {mult} = {channels} channels at level {level}: GroupNorm needs a multiple of groups ({groups})"
    )]
    Groups {
        /// `model_channels`.
        base: usize,
        /// The level's multiplier.
        mult: usize,
        /// Its channels.
        channels: usize,
        /// The level.
        level: usize,
        /// `groups`.
        groups: usize,
    },
    /// An attended level's channels that are not whole heads.
    #[error(
        "{channels} channels at level {level} have attention: they must be a multiple of head_dim ({head_dim})"
    )]
    Heads {
        /// Its channels.
        channels: usize,
        /// The level.
        level: usize,
        /// `head_dim`.
        head_dim: usize,
    },
    /// α asked of a model trained without accentuation.
    #[error("this world model was not trained with --accentuation, so it has no α input")]
    NoAlphaInput,
    /// An α below 1 or not finite.
    #[error("α must be a finite value >= 1, got {0}")]
    Alpha(f32),
    /// A noise scale asked of a diffusion model.
    #[error("a diffusion model's noise starts its DDIM sampling; it has no temperature")]
    NoTemperature,
    /// A noise scale outside [0, 1] or not finite.
    #[error("the noise scale must be a finite value in [0, 1], got {0}")]
    NoiseScale(f32),
    /// Actions of another width than the model reads.
    #[error("actions have {given} entries, the world model reads {reads}")]
    ActionWidth {
        /// The actions' width.
        given: usize,
        /// The model's.
        reads: usize,
    },
}
