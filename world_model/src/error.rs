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

/// Why a network cannot be run by the direct kernels (a layer they do not support).
#[derive(Debug, thiserror::Error)]
#[error("layer {layer}: {message}")]
pub struct UnsupportedLayer {
    layer: String,
    message: String,
}

impl UnsupportedLayer {
    /// `layer` cannot run on these kernels, because of `message`.
    pub fn new(layer: &str, message: impl Into<String>) -> Self {
        Self { layer: layer.into(), message: message.into() }
    }
}
