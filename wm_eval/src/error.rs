//! What can stop `wm eval`: its inputs, its outputs, and the evaluation between them.
//! Each wrapped error keeps its own message and source (the command prints the chain).

use std::path::PathBuf;

/// A failed `wm eval`.
#[derive(Debug, thiserror::Error)]
pub enum WmEvalError {
    /// The output folder (or an input placed inside it).
    #[error(transparent)]
    Output(#[from] runner::output::OutputError),
    /// The device named by the environment.
    #[error(transparent)]
    Device(#[from] nn::device::DeviceError),
    /// A world model or judge folder.
    #[error(transparent)]
    Input(#[from] runner::RunError),
    /// The dataset as the world models read it.
    #[error(transparent)]
    Data(#[from] world_model::WorldModelError),
    /// The dataset's arrays or attributes.
    #[error(transparent)]
    Replay(#[from] harness::replay::ReplayError),
    /// Goal-free frames that cannot be made from the dataset.
    #[error(transparent)]
    GoalFree(#[from] scenarios::pusht::goal_free::GoalFreeError),
    /// A rollout.
    #[error(transparent)]
    Eval(#[from] world_model::eval::EvalError),
    /// The filmstrip.
    #[error(transparent)]
    Png(#[from] reports::png::PngError),
    /// A `--start` step no video can start at (the message names the step and its episode).
    #[error("{0}")]
    Start(String),
    /// No episode is long enough for a 64-frame video.
    #[error("{}: no {which} has {frames} frames", data.display())]
    NoVideos {
        /// The dataset.
        data: PathBuf,
        /// "episode" or "held-out episode".
        which: &'static str,
        /// Frames a video needs (context and generated).
        frames: usize,
    },
    /// `--judge` without whole-episode videos to read.
    #[error("--judge reads whole-episode videos: give --full-episodes of at least 1")]
    JudgeWithoutEpisodes,
    /// A judge of frames of another size than the dataset's.
    #[error("--judge {}: it reads {judged}x{judged} frames, and {} has {frames}x{frames}", judge.display(), data.display())]
    JudgeSize {
        /// The judge folder.
        judge: PathBuf,
        /// The dataset.
        data: PathBuf,
        /// The judge's frame side.
        judged: usize,
        /// The dataset's frame side.
        frames: usize,
    },
    /// `eval.json` could not be written.
    #[error("writing {}: {source}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}
