//! A dataset written as any other output: staged in `OUT.partial` by [`Staged`] (so
//! the inputs are checked, the output is locked and a failure leaves nothing behind),
//! streamed episode by episode, and moved into place only when complete.

use std::path::{Path, PathBuf};

use harness::replay::attrs::DatasetAttrs;
use harness::replay::{EpisodeArrays, ReplaySpec, ReplayWriter};

use super::{Inputs, OutputError, Staged};

type Result<T, E = OutputError> = std::result::Result<T, E>;

/// A dataset being written to `--out`.
pub struct StagedDataset {
    staged: Staged,
    writer: ReplayWriter,
}

impl StagedDataset {
    /// Starts a dataset at `out` for a command reading `inputs` (an existing `out` is
    /// refused unless `force`, and replaced only by [`StagedDataset::finish`]).
    ///
    /// # Errors
    /// As [`Staged::new`], or the dataset's folders cannot be made.
    pub fn create(out: &Path, force: bool, inputs: &Inputs, spec: ReplaySpec) -> Result<Self> {
        let staged = Staged::new(out, force, inputs)?;
        let writer = ReplayWriter::create_in(staged.dir(), spec)
            .map_err(|source| OutputError::Dataset { dir: staged.dir().to_path_buf(), source })?;
        Ok(Self { staged, writer })
    }

    /// Appends one episode.
    ///
    /// # Errors
    /// Arrays that disagree with the layout, or an I/O failure.
    pub fn append(&mut self, ep: &EpisodeArrays) -> Result<()> {
        let dir = self.staged.dir();
        self.writer.append(ep).map_err(|source| OutputError::Dataset { dir: dir.to_path_buf(), source })
    }

    /// Writes the metadata and `attrs` (under the root's `evalharness`), then moves the
    /// dataset into place.
    ///
    /// # Errors
    /// An I/O failure; the old `out` is then as it was.
    pub fn finish(self, attrs: &DatasetAttrs) -> Result<PathBuf> {
        let dir = self.staged.dir().to_path_buf();
        self.writer.finish(&attrs.to_root()).map_err(|source| OutputError::Dataset { dir, source })?;
        self.staged.commit()
    }
}
