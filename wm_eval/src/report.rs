//! `eval.json`, typed: what `wm eval` measured and on which videos.
//!
//! It is written through `serde_json::Value`, whose maps keep keys in alphabetical
//! order, so that the file reads as it did when it was assembled with `json!`.

use std::path::{Path, PathBuf};

use serde::Serialize;
use world_model::eval::EvalRow;

use crate::motion::MotionBin;
use crate::score::ScoreRow;
use crate::success::SuccessRow;
use crate::{Windows, WmEvalError};

/// `eval.json`.
#[derive(Debug, Serialize)]
pub struct EvalFile {
    /// Every video-metric row: each model's 64-frame and whole-episode rows, then the
    /// references.
    pub models: Vec<EvalRow>,
    /// Each model's sampling settings.
    pub sampling: Vec<Sampling>,
    /// What the reference rows are.
    pub references_note: &'static str,
    /// The 64-frame rows' SSIM by block motion, or why not.
    pub ssim_by_block_motion: ByMotion,
    /// Each model's open-loop score row (Push-T datasets), then "persistence".
    pub open_loop_scores: Vec<ScoreRow>,
    /// How the scores were read, or why there are none.
    pub open_loop_scores_note: String,
    /// Each model's open-loop success check (`--judge`).
    pub open_loop_success: Vec<SuccessRow>,
    /// How success was read, or "not measured".
    pub open_loop_success_note: String,
    /// The dataset.
    pub data: PathBuf,
    /// Which episodes the videos come from.
    pub episodes_from: &'static str,
    /// How the 64-frame windows were chosen.
    pub windows_64: WindowsUsed,
    /// Each 64-frame video's episode.
    pub episodes_64: Vec<usize>,
    /// Each 64-frame video's first context step.
    pub starts_64: Vec<usize>,
    /// Each whole-episode video's episode.
    pub episodes_whole: Vec<usize>,
    /// 64-frame videos.
    pub videos_64: usize,
    /// Whole-episode videos.
    pub videos_episode: usize,
    /// Videos generated together.
    pub batch: usize,
    /// Seed of the generator noise.
    pub seed: u64,
    /// What the filmstrip's rows show.
    pub filmstrip: String,
}

/// How the 64-frame windows were chosen: `first` or `random` ([`Windows`]), or
/// `given (--start)`.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum WindowsUsed {
    /// Chosen by `--windows`.
    Chosen(Windows),
    /// Given by `--start`.
    Given(&'static str),
}

/// One model's sampling settings.
#[derive(Debug, Serialize)]
pub struct Sampling {
    /// The model's name.
    pub name: String,
    /// Its action-accentuation strength (none for a model without accentuation).
    pub alpha: Option<f32>,
    /// Its sampling-noise scale.
    pub noise_scale: f32,
}

/// The SSIM-by-block-motion breakdown, or why there is none.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum ByMotion {
    /// The bins.
    Bins {
        /// What the breakdown is.
        note: &'static str,
        /// The bins, from still to pushed across the workspace.
        bins: Vec<MotionBin>,
    },
    /// Why not.
    Unavailable {
        /// "not available: …".
        note: String,
    },
}

impl EvalFile {
    /// Writes the file to `path` (keys in alphabetical order, pretty-printed, a final newline).
    ///
    /// # Errors
    /// [`WmEvalError::Write`] naming the file.
    pub fn write(&self, path: &Path) -> Result<(), WmEvalError> {
        let err = |source| WmEvalError::Write { path: path.to_path_buf(), source };
        let value = serde_json::to_value(self).map_err(|e| err(e.into()))?;
        let mut text = serde_json::to_string_pretty(&value).map_err(|e| err(e.into()))?;
        text.push('\n');
        std::fs::write(path, text).map_err(err)
    }
}
