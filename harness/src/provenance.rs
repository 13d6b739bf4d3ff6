//! What a model folder records of how it was made, typed: an autoencoder's and a world
//! model's `provenance.json` (what was trained, on which data, by which command and
//! commit, in which sessions, to which step and held-out metric), the data a trainer
//! read, the run it started from and each export since.
//!
//! The structs declare their fields in alphabetical order: serde writes them in
//! declaration order, and these files were written with sorted keys before they were
//! typed, so their fields keep their order (a dataset's recipe now writes its fields in
//! [`Recipe`]'s order, as its dataset does). A field this version does not
//! know (a file written by another version) is kept in `other` and written back, so
//! `wm export` never drops what a file said. Another run's provenance nested in this one
//! (the run a model started from, a replacing autoencoder's) is kept whole, as that file
//! was: it may come from any version.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::replay::attrs::Recipe;
use crate::sessions::Session;

/// Which episodes a trainer held out for its evaluation.
pub const HELD_OUT: &str = "episodes with index % 10 == 9";

/// A provenance file that could not be read, parsed or written.
#[derive(Debug, thiserror::Error)]
pub enum ProvenanceError {
    /// The file cannot be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not the provenance it should be.
    #[error("{}: {source}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// Why.
        source: serde_json::Error,
    },
}

/// One export of a model folder (`wm export`, `export-policies`), oldest first.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Exported {
    /// The inference strength `wm export --alpha` set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<f32>,
    /// `export-policies`: each inference setting it changed, `[before, after]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub changed: Option<BTreeMap<String, [usize; 2]>>,
    /// The export's command line.
    pub command: String,
    /// The commit of the binary that exported.
    pub commit: String,
    /// The folder exported from.
    pub from: String,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// The frames a world model or autoencoder was trained on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramesUsed {
    /// How the dataset was made (`None` for one evalharness did not make).
    pub collected_with: Option<Recipe>,
    /// Episodes in the dataset.
    pub episodes: usize,
    /// Frames in the dataset.
    pub frames: usize,
    /// Which episodes were held out ([`HELD_OUT`]).
    pub held_out: String,
    /// The dataset as given.
    pub path: String,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

impl FramesUsed {
    /// `path`'s `episodes` and `frames`, made as `collected_with` says.
    pub fn new(path: &Path, episodes: usize, frames: usize, collected_with: Option<Recipe>) -> Self {
        Self {
            collected_with,
            episodes,
            frames,
            held_out: HELD_OUT.to_string(),
            path: path.display().to_string(),
            other: BTreeMap::new(),
        }
    }
}

/// A run this one started from, and that run's provenance as it was then (`None` when
/// it had none).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Source {
    /// Its folder, as given.
    pub path: String,
    /// Its `provenance.json`, whole.
    pub provenance: Option<Value>,
}

/// `wm export --autoencoder`: the decoder a world model folder uses instead of the one
/// its latents were trained with.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoencoderReplaced {
    /// The autoencoder now used, relative to the exported folder.
    pub now: String,
    /// Its `provenance.json`, whole.
    pub now_provenance: Option<Value>,
    /// The autoencoder the world model was trained on.
    pub trained_on: String,
}

/// An autoencoder's held-out metrics (`None`: not measured, or not finite).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoencoderMetrics {
    /// Mean squared error of the reconstructions, values in [0, 1].
    pub held_out_mse: Option<f64>,
    /// Their PSNR.
    pub held_out_psnr_db: Option<f64>,
}

/// A world model's held-out metric.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldModelMetrics {
    /// Mean squared error of one predicted chunk's latents.
    pub held_out_one_chunk_latent_mse: Option<f64>,
}

/// `provenance.json` of `train autoencoder`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AutoencoderProvenance {
    /// The last session's command line.
    pub command: String,
    /// The commit of its binary.
    pub commit: String,
    /// The frames it was trained on.
    pub data: FramesUsed,
    /// A narrower decoder's channels (`None`: the encoder's mirror).
    pub decoder_channels: Option<[usize; 4]>,
    /// Training seconds over all sessions.
    pub elapsed_s: f64,
    /// The autoencoder whose encoder it kept, training only a decoder.
    pub encoder_from: Option<Source>,
    /// Whether the run reached its step total.
    pub finished: bool,
    /// Held-out reconstruction metrics.
    pub metrics: AutoencoderMetrics,
    /// The run's seed.
    pub seed: u64,
    /// Its sessions, oldest first.
    pub sessions: Vec<Session>,
    /// Steps done.
    pub steps: u64,
    /// What the folder holds, in words.
    pub what: String,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// `provenance.json` of `train world-model`, and of a folder `wm export` made from one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WorldModelProvenance {
    /// The autoencoder of its latents, relative to the folder (`None`: pixels).
    pub autoencoder: Option<String>,
    /// `wm export --autoencoder`: the decoder used instead.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub autoencoder_replaced: Option<AutoencoderReplaced>,
    /// The last session's command line.
    pub command: String,
    /// The commit of its binary.
    pub commit: String,
    /// The frames it was trained on.
    pub data: FramesUsed,
    /// Training seconds over all sessions.
    pub elapsed_s: f64,
    /// Each export since training, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exported: Vec<Exported>,
    /// Whether the run reached its step total.
    pub finished: bool,
    /// Which frames it saw: as stored, or re-rendered without the goal.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<String>,
    /// The run it was warm-started from.
    pub init_from: Option<Source>,
    /// Held-out metric.
    pub metrics: WorldModelMetrics,
    /// The run's seed.
    pub seed: u64,
    /// Its sessions, oldest first.
    pub sessions: Vec<Session>,
    /// Steps done.
    pub steps: u64,
    /// What the folder holds, in words.
    pub what: String,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// `provenance.json` of `import world-model`: what was read, by which command.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ImportedProvenance {
    /// The import's command line.
    pub command: String,
    /// The commit of its binary.
    pub commit: String,
    /// Each export since the import, oldest first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exported: Vec<Exported>,
    /// What the import read (its file, SHA-256, step and tensors), whole.
    pub import: Value,
    /// Fields of another version.
    #[serde(flatten)]
    pub other: BTreeMap<String, Value>,
}

/// A world-model folder's provenance: trained here, or imported.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum WorldModelOrigin {
    /// `train world-model`'s.
    Trained(Box<WorldModelProvenance>),
    /// `import world-model`'s.
    Imported(ImportedProvenance),
}

impl WorldModelOrigin {
    /// The training steps the provenance records (an import records none).
    pub fn steps(&self) -> Option<u64> {
        match self {
            Self::Trained(p) => Some(p.steps),
            Self::Imported(_) => None,
        }
    }

    /// The exports since, oldest first, to add one to.
    pub fn exported_mut(&mut self) -> &mut Vec<Exported> {
        match self {
            Self::Trained(p) => &mut p.exported,
            Self::Imported(p) => &mut p.exported,
        }
    }
}

/// Reads a provenance file as `T`.
///
/// # Errors
/// [`ProvenanceError`] naming `path` when it cannot be read or is not a `T`.
pub fn read<T: DeserializeOwned>(path: &Path) -> Result<T, ProvenanceError> {
    let text =
        std::fs::read_to_string(path).map_err(|source| ProvenanceError::Io { path: path.into(), source })?;
    serde_json::from_str(&text).map_err(|source| ProvenanceError::Parse { path: path.into(), source })
}

/// A run's provenance file `dir/provenance.json`, whole, to nest in another run's (`None`
/// when it has none or it does not parse: the nesting run records what there is).
pub fn snapshot(dir: &Path) -> Option<Value> {
    read(&dir.join("provenance.json")).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every provenance file shipped under `checkpoints/` reads as its type and writes
    /// back as the same JSON (the fields' order included), so typing it dropped nothing.
    #[test]
    fn shipped_files_read_and_write_back_unchanged() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../checkpoints");
        let mut seen = 0;
        for task in ["pusht", "lift", "can"] {
            for entry in std::fs::read_dir(root.join(task)).expect("checkpoints/<task>") {
                let dir = entry.expect("entry").path();
                let path = dir.join("provenance.json");
                let name = dir.file_name().and_then(|n| n.to_str()).unwrap_or_default();
                if !path.is_file() {
                    continue;
                }
                let text = std::fs::read_to_string(&path).expect("readable");
                let again = if name.starts_with("world_model") {
                    let p: WorldModelProvenance = read(&path).expect("a world model's");
                    assert!(p.other.is_empty() && p.data.other.is_empty(), "{}", path.display());
                    serde_json::to_string_pretty(&p)
                } else if name == "autoencoder" {
                    let p: AutoencoderProvenance = read(&path).expect("an autoencoder's");
                    assert!(p.other.is_empty() && p.data.other.is_empty(), "{}", path.display());
                    serde_json::to_string_pretty(&p)
                } else {
                    continue;
                };
                // Older files leave out the entries that are null (`decoder_channels`,
                // `encoder_from`), which the type writes as null: the same statement.
                let v = |t: &str| {
                    let mut v: Value = serde_json::from_str(t).expect("JSON");
                    v.as_object_mut().expect("an object").retain(|_, x| !x.is_null());
                    v
                };
                assert_eq!(v(&again.expect("serialises")), v(&text), "{}", path.display());
                seen += 1;
            }
        }
        // Push-T: an autoencoder and four world models; Lift: an autoencoder and three; Can: two.
        assert!(seen >= 10, "only {seen} provenance files found");
    }
}
