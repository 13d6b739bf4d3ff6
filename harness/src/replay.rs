//! Episode datasets in the diffusion_policy / GPC replay-buffer layout (zarr v2).
//!
//! ```text
//! DIR/.zattrs                 {"evalharness": {...provenance, per-episode seeds...}}
//! DIR/data/img                N x H x W x 3   uint8   observation before each action
//! DIR/data/action             N x A           float32 the action taken after it
//! DIR/data/state              N x S           float32 privileged state (first 2 = agent xy)
//! DIR/data/<extra>            N               float32 optional per-step values (e.g. coverage)
//! DIR/meta/episode_ends       E               int64   exclusive cumulative step counts
//! ```
//! [`ReplayWriter`] writes into `DIR.partial/` and renames it to `DIR` only when
//! everything is on disk, so an interrupted collection never looks complete.
//! [`ReplayReader`] also opens a folder of such groups (`*.zarr`, in name order) as one
//! dataset, as GPC stores its world-model data, with float32 images in [0, 255].

use std::fs;
use std::path::{Path, PathBuf};

use serde_json::Value;

use crate::zarr::{ArrayWriter, DType, ZarrError, write_group};

/// Errors of dataset reading and writing, naming the dataset.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The store failed underneath.
    #[error(transparent)]
    Zarr(#[from] ZarrError),
    /// The output exists and overwriting was not asked for.
    #[error("{0} already exists (pass --force to replace it)")]
    Exists(PathBuf),
    /// The folder is not a replay buffer of the expected layout.
    #[error("{path} is not a replay-buffer dataset: {reason}")]
    Layout {
        /// The dataset.
        path: PathBuf,
        /// What is missing or inconsistent.
        reason: String,
    },
    /// Plain I/O (creating, removing, renaming folders).
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
}

/// Shapes of a dataset's per-step arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplaySpec {
    /// Image height and width.
    pub image_hw: [usize; 2],
    /// Action dimension.
    pub action_dim: usize,
    /// State dimension.
    pub state_dim: usize,
    /// Names of optional per-step scalar arrays under `data/`.
    pub extras: Vec<String>,
}

/// One episode's arrays, rows in step order.
#[derive(Clone, Debug, Default)]
pub struct EpisodeArrays {
    /// `steps x H x W x 3` bytes.
    pub img: Vec<u8>,
    /// `steps x action_dim`.
    pub action: Vec<f32>,
    /// `steps x state_dim`.
    pub state: Vec<f32>,
    /// One `steps`-long vector per extra, in [`ReplaySpec::extras`] order.
    pub extras: Vec<Vec<f32>>,
}

fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Streams episodes into a new dataset.
pub struct ReplayWriter {
    /// Where [`ReplayWriter::finish`] moves the dataset; `None` when the caller
    /// staged the folder itself ([`ReplayWriter::create_in`]) and moves it.
    path: Option<PathBuf>,
    tmp: PathBuf,
    spec: ReplaySpec,
    img: ArrayWriter,
    action: ArrayWriter,
    state: ArrayWriter,
    extras: Vec<ArrayWriter>,
    ends: Vec<i64>,
}

impl ReplayWriter {
    /// Starts a dataset at `path` (refused if it exists, unless `force`: then the old
    /// one is replaced by [`ReplayWriter::finish`], never before).
    ///
    /// # Errors
    /// [`ReplayError::Exists`], or I/O errors naming the folder.
    pub fn create(path: &Path, spec: ReplaySpec, force: bool) -> Result<Self, ReplayError> {
        // With `force`, an existing dataset is replaced only by `finish`, once the new
        // one is complete.
        if path.exists() && !force {
            return Err(ReplayError::Exists(path.to_path_buf()));
        }
        let mut tmp = path.as_os_str().to_owned();
        tmp.push(".partial");
        let tmp = PathBuf::from(tmp);
        if tmp.exists() {
            fs::remove_dir_all(&tmp).map_err(|source| ReplayError::Io { path: tmp.clone(), source })?;
        }
        let mut w = Self::create_in(&tmp, spec)?;
        w.path = Some(path.to_path_buf());
        Ok(w)
    }

    /// Starts a dataset in the folder `dir`, which the caller made (empty, or holding
    /// only files of its own) and moves into place when [`ReplayWriter::finish`] returns.
    ///
    /// # Errors
    /// I/O errors naming the folder.
    pub fn create_in(dir: &Path, spec: ReplaySpec) -> Result<Self, ReplayError> {
        let tmp = dir.to_path_buf();
        write_group(&tmp, None)?;
        write_group(&tmp.join("data"), None)?;
        write_group(&tmp.join("meta"), None)?;
        let [h, w] = spec.image_hw;
        let d = tmp.join("data");
        // ~2.8 MB of raw pixels per image chunk at 96x96; 8192 rows per low-dim chunk.
        let img = ArrayWriter::create(&d.join("img"), DType::U8, &[h, w, 3], 100)?;
        let action = ArrayWriter::create(&d.join("action"), DType::F32, &[spec.action_dim], 8192)?;
        let state = ArrayWriter::create(&d.join("state"), DType::F32, &[spec.state_dim], 8192)?;
        let extras = spec
            .extras
            .iter()
            .map(|name| ArrayWriter::create(&d.join(name), DType::F32, &[], 8192))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self { path: None, tmp, spec, img, action, state, extras, ends: Vec::new() })
    }

    /// Appends one episode.
    ///
    /// # Errors
    /// [`ReplayError::Layout`] if the arrays disagree with the spec or each other;
    /// I/O errors from the store.
    pub fn append(&mut self, ep: &EpisodeArrays) -> Result<(), ReplayError> {
        let [h, w] = self.spec.image_hw;
        let steps = ep.img.len() / (h * w * 3);
        let bad = |reason: String| ReplayError::Layout { path: self.tmp.clone(), reason };
        if ep.img.len() != steps * h * w * 3
            || ep.action.len() != steps * self.spec.action_dim
            || ep.state.len() != steps * self.spec.state_dim
            || ep.extras.len() != self.extras.len()
            || ep.extras.iter().any(|e| e.len() != steps)
        {
            return Err(bad(format!("episode {} has inconsistent array lengths", self.ends.len())));
        }
        self.img.append(&ep.img)?;
        self.action.append(&f32_bytes(&ep.action))?;
        self.state.append(&f32_bytes(&ep.state))?;
        for (wr, v) in self.extras.iter_mut().zip(&ep.extras) {
            wr.append(&f32_bytes(v))?;
        }
        let last = self.ends.last().copied().unwrap_or(0);
        self.ends.push(last + steps as i64);
        Ok(())
    }

    /// Episodes appended so far.
    pub fn episodes(&self) -> usize {
        self.ends.len()
    }

    /// Writes the metadata and `attrs` (stored under the root's `.zattrs`), then
    /// moves the dataset into place (with [`ReplayWriter::create`]; returns its folder).
    ///
    /// # Errors
    /// I/O errors naming the file.
    pub fn finish(self, attrs: &Value) -> Result<PathBuf, ReplayError> {
        self.img.finish()?;
        self.action.finish()?;
        self.state.finish()?;
        for e in self.extras {
            e.finish()?;
        }
        let mut ends = ArrayWriter::create(
            &self.tmp.join("meta/episode_ends"),
            DType::I64,
            &[],
            self.ends.len().max(1),
        )?;
        ends.append(&self.ends.iter().flat_map(|e| e.to_le_bytes()).collect::<Vec<u8>>())?;
        ends.finish()?;
        write_group(&self.tmp, Some(attrs))?;
        let Some(path) = self.path else { return Ok(self.tmp) };
        if path.exists() {
            fs::remove_dir_all(&path).map_err(|source| ReplayError::Io { path: path.clone(), source })?;
        }
        fs::rename(&self.tmp, &path).map_err(|source| ReplayError::Io { path: path.clone(), source })?;
        Ok(path)
    }
}

pub mod attrs;
mod column;
pub mod origin;
mod reader;

pub use column::Column;
pub use reader::ReplayReader;

#[cfg(test)]
mod tests;
