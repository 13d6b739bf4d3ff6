//! Recorded MuJoCo episodes ([`engine::Trajectory`]) written as a training dataset,
//! in the zarr layout of the task's scripted `collect` ([`harness::scripted::Scripted`]).
//!
//! Why one place: `collect --policy` records policy checkpoints' closed-loop
//! rollouts, and `simulate --replay-imagined --record` the MuJoCo replays of the
//! actions a policy took in the world model. Both feed the same trainers, so both
//! must write the layout the task declares.

use std::path::{Path, PathBuf};

use crate::error::{Result, SimError};
use engine::Trajectory;
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::scripted::Recorded;
use harness::task::Task;

use crate::collect::{episode_entry, scripted_of, with_source};
use runner::output::Inputs;
use runner::output::dataset::StagedDataset;

/// A dataset being written, episode by episode; nothing appears at its path until
/// [`Sink::finish`] (it is staged into `PATH.partial`, [`StagedDataset`]).
pub(super) struct Sink<'t> {
    writer: StagedDataset,
    task: &'t dyn Task,
    header: DatasetAttrs,
}

impl<'t> Sink<'t> {
    /// A dataset of `task`'s episodes at `out`, in the task's layout, for a command reading
    /// `inputs` (refused if `out` exists, unless `force`, or if it overlaps an input, or if
    /// the task declares no dataset layout).
    pub fn create(task: &'t dyn Task, out: &Path, force: bool, inputs: &Inputs) -> Result<Self> {
        let layout = scripted_of(task)?.layout();
        Ok(Self {
            writer: StagedDataset::create(out, force, inputs, layout.spec)?,
            task,
            header: layout.header,
        })
    }

    /// Appends one episode, labelled `behaviour`; returns its score and its entry in
    /// the dataset's attributes.
    pub fn append(&mut self, t: &Trajectory, behaviour: &str) -> Result<(f64, EpisodeEntry)> {
        let recorded = Recorded {
            seed: t.seed,
            frames: &t.frames,
            states: &t.states,
            actions: &t.actions,
            raw: &t.raw,
            goal: t.goal,
            score: t.score,
            success: t.success,
        };
        let arrays = scripted_of(self.task)?.recorded_arrays(&recorded).map_err(SimError::from_task)?;
        self.writer.append(&arrays)?;
        let entry = episode_entry(self.task, t.seed, behaviour, t.actions.len(), (t.score, t.success));
        Ok((t.score, entry))
    }

    /// Writes the attributes (how the episodes were made, the step limit, one entry
    /// per episode) and moves the dataset into place; returns its path.
    pub fn finish(
        self,
        seed_start: u64,
        source: Source,
        max_steps: usize,
        episodes: Vec<EpisodeEntry>,
    ) -> Result<PathBuf> {
        let attrs = with_source(self.header, seed_start, source, max_steps, episodes);
        Ok(self.writer.finish(&attrs)?)
    }
}
