//! A judge folder's provenance (`judge.json`'s `provenance`), typed: how the judge was
//! made (trained by `train judge`, written by hand, or imported), and the persistence
//! rule `read-judge --out` chose for it on which data.
//!
//! Fields are declared in alphabetical order, the order the file had when it was written
//! as a sorted JSON map. A field this version does not know (a judge written by another
//! version) is kept in `other` and written back. The record of an import, different for
//! every format, is kept whole.

use std::collections::BTreeMap;

use harness::replay::attrs::Recipe;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::metrics::{EpisodeReading, JudgeMetrics};

/// Training hyper-parameters (written into `judge.json`'s provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JudgeTrainConfig {
    /// Optimiser steps.
    pub steps: u64,
    /// Frames per step.
    pub batch: usize,
    /// Peak learning rate (AdamW).
    pub lr: f64,
    /// Seed of the weights and the frame order.
    pub seed: u64,
    /// Draw half of each batch from frames above the threshold.
    pub balance: bool,
    /// Augment with the 8 symmetries of the square (Push-T only).
    pub symmetries: bool,
    /// Evaluate on the held-out frames every this many steps.
    pub eval_every: u64,
}

/// The episodes a judge was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LabelledData {
    /// How the dataset was made (`None` for one evalharness did not make).
    pub collected_with: Option<Recipe>,
    /// Episodes in the dataset.
    pub episodes: usize,
    /// The dataset's fingerprint (`None` when it could not be taken).
    pub fingerprint: Option<String>,
    /// Labelled frames.
    pub frames: usize,
    /// Which episodes were held out.
    pub held_out: String,
    /// The dataset as given.
    pub path: String,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// What `read-judge` reports: a judge's reading of a dataset's whole episodes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PersistenceReport {
    /// The persistence value that reads most episodes right (smallest on a tie).
    pub best: usize,
    /// The judge's frame metrics over every judged frame.
    pub frames: JudgeMetrics,
    /// One reading per persistence value, in the order given.
    pub readings: Vec<EpisodeReading>,
}

/// How `read-judge --out` chose the judge's persistence.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Persistence {
    /// Its command line.
    pub command: String,
    /// The commit of its binary.
    pub commit: String,
    /// The dataset read, as given.
    pub data: String,
    /// Episodes read.
    pub episodes: usize,
    /// The dataset's fingerprint (`None` when it could not be taken).
    pub fingerprint: Option<String>,
    /// The judge folder it started from.
    pub from: String,
    /// What it read.
    pub report: PersistenceReport,
}

/// How a judge was made.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JudgeProvenance {
    /// The command line that made it (absent for a hand-written rule).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub command: Option<String>,
    /// The commit of that binary.
    pub commit: String,
    /// The episodes it was trained on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data: Option<LabelledData>,
    /// A hand-written rule: its type.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hand_written: Option<String>,
    /// What an import read and how, whole.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub import: Option<Value>,
    /// Why training stopped before its step total (`--max-minutes`, Ctrl-C).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub out_of_time: Option<String>,
    /// The persistence rule `read-judge --out` chose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub persistence: Option<Persistence>,
    /// The training seed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    /// The training run's sessions, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sessions: Vec<harness::sessions::Session>,
    /// The training settings.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub train: Option<JudgeTrainConfig>,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;

    /// The shipped judges' provenance reads as its type and writes back as the same JSON.
    #[test]
    fn shipped_judges_read_and_write_back_unchanged() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../checkpoints");
        for task in ["lift", "can"] {
            let path = root.join(task).join("judge/judge.json");
            let v: Value =
                serde_json::from_str(&std::fs::read_to_string(&path).expect("readable")).expect("JSON");
            let typed: JudgeProvenance = serde_json::from_value(v["provenance"].clone())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            assert!(typed.other.is_empty(), "{}: {:?}", path.display(), typed.other.keys());
            assert_eq!(
                serde_json::to_value(&typed).expect("serialises"),
                v["provenance"],
                "{}",
                path.display()
            );
        }
    }
}
