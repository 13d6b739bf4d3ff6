//! The batches of one `rank` process: which of the run's batches it runs (its shard's
//! share, or those it claims with the other shards of `rank --processes`; of those,
//! the seeds a resumed run lacks), running them on the engine's workers with every
//! finished batch appended whole to `episodes.jsonl` and its frames kept for the
//! filmstrips, and a resumed run's rows left in a straight run's order.
//!
//! A policy whose batch fails is reported and left out; a world model or a judge that
//! fails stops the run (they would fail every policy alike), the rows of the batches
//! before kept.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use engine::schedule::{self, Batch, BatchResult};
use engine::{EngineError, Setup, Timing};
use harness::policy::Policy;
use harness::results::{EpisodeRow, FailedPolicy};
use harness::rows::append_rows;
use world_model::model::WorldModel;

use crate::claims::Claims;
use crate::error::RunError;
use crate::media::kept::{FOLDER, Kept};

/// What one process of a run runs.
pub struct Batches<'a> {
    /// Every checkpoint's name, in run order (also those that failed to load).
    pub names: &'a [String],
    /// The policies that loaded, each with its index into `names`.
    pub loaded: &'a [(usize, Box<dyn Policy>)],
    /// The run's seeds, cut into batches of `--batch`.
    pub batches: &'a [&'a [u64]],
    /// This process's shard `(i, n)` of the run.
    pub shard: (usize, usize),
    /// The claims folder the shards of `rank --processes` share, if any.
    pub claims: Option<&'a Path>,
    /// Worker threads.
    pub jobs: usize,
    /// The run's folder (`episodes.jsonl`, the kept frames).
    pub out: &'a Path,
    /// The world model and the learned judge, named when they fail.
    pub world_model: &'a Path,
    /// The learned judge's folder (none: the task's own judge).
    pub judge: Option<&'a Path>,
}

/// What the batches left: every row (resumed ones too), in a straight run's order, the
/// policies that failed, the time spent and the frames kept for the filmstrips.
pub struct Ran {
    /// The rows.
    pub rows: Vec<EpisodeRow>,
    /// The policies that failed to load or run.
    pub failed: Vec<FailedPolicy>,
    /// The engine's time, summed over batches.
    pub timing: Timing,
    /// The kept frames.
    pub kept: Kept,
}

impl Batches<'_> {
    /// The folder of the run's kept frames.
    #[must_use]
    pub fn kept_dir(&self) -> PathBuf {
        self.out.join(FOLDER)
    }

    /// Runs this process's batches after the `rows` a resumed run holds (whole batches
    /// only), with `failed` the policies that did not load; `record` keeps frames for
    /// the filmstrips; `advance(n)` counts episodes done or skipped.
    ///
    /// # Errors
    /// A world model or judge that failed (the rows before kept), or a file that could
    /// not be written or read.
    pub fn run(
        &self,
        mut rows: Vec<EpisodeRow>,
        mut failed: Vec<FailedPolicy>,
        setup: &Setup,
        wm: &WorldModel,
        advance: &dyn Fn(u64),
    ) -> Result<Ran, RunError> {
        let (shard, shards) = self.shard;
        let claims = self.claims.map(|d| Claims::open(d, shard)).transpose()?;
        // Branch rows each (policy, seed) already has.
        let mut have: HashMap<(&str, u64), usize> = HashMap::new();
        for r in &rows {
            *have.entry((r.policy.as_str(), r.seed)).or_default() += 1;
        }
        let (mut jobs, mut keys): (Vec<Batch>, Vec<String>) = (Vec::new(), Vec::new());
        for (li, (pi, _)) in self.loaded.iter().enumerate() {
            for (bi, batch) in self.batches.iter().enumerate() {
                let name = self.names[*pi].as_str();
                if claims.is_none() && (pi * self.batches.len() + bi) % shards != shard {
                    advance(batch.len() as u64);
                    continue;
                }
                let todo: Vec<u64> = batch
                    .iter()
                    .copied()
                    .filter(|s| have.get(&(name, *s)).copied().unwrap_or(0) < 2)
                    .collect();
                advance((batch.len() - todo.len()) as u64);
                if !todo.is_empty() {
                    jobs.push(Batch { policy: li, seeds: todo });
                    keys.push(Claims::key(*pi, bi));
                }
            }
        }
        let policies: Vec<&dyn Policy> = self.loaded.iter().map(|(_, p)| p.as_ref()).collect();
        let kept_dir = self.kept_dir();
        let mut kept = if setup.record { Kept::open(&kept_dir, &rows)? } else { Kept::default() };
        let jsonl = self.out.join("episodes.jsonl");
        let mut done = |j: usize, out: BatchResult| -> Result<(), RunError> {
            let (name, todo) = (&self.names[self.loaded[jobs[j].policy].0], &jobs[j].seeds);
            match out {
                Ok(new) => {
                    // Batches are appended whole, and a resume drops any part of one.
                    append_rows(&jsonl, &new.rows)?;
                    kept.add(name, &new.rows, new.frames)?;
                    rows.extend(new.rows);
                    advance(todo.len() as u64);
                }
                // The world model failing is not the policy's fault and would fail every
                // policy alike: stop the run once, naming the model.
                Err(EngineError::WorldModel { source, .. }) => {
                    return Err(RunError::WorldModel {
                        model: self.world_model.to_path_buf(),
                        policy: name.clone(),
                        seeds: todo.clone(),
                        source: Box::new(source),
                    });
                }
                // A judge that scores nonsense would make every policy's imagined rows wrong.
                Err(e @ EngineError::Judge { .. }) => {
                    let judge = self.judge.map_or_else(
                        || "the task's own judge".to_string(),
                        |d| format!("judge {}", d.display()),
                    );
                    return Err(RunError::Judge { judge, source: Box::new(e) });
                }
                Err(e) => {
                    let e = with_sources(&e);
                    tracing::error!("policy {name}: {e}; continuing with the other policies");
                    failed.push(FailedPolicy { policy: name.clone(), error: e });
                }
            }
            Ok(())
        };
        let timing = match &claims {
            Some(c) => {
                crate::claims::run_claimed::<RunError>(&policies, &jobs, &keys, c, setup, wm, &mut done)?
            }
            None => schedule::run_batches::<RunError>(&policies, &jobs, setup, wm, self.jobs, &mut done)?,
        };
        Ok(Ran { rows, failed, timing, kept })
    }
}

/// An error and each of its sources, joined by `: ` (what `anyhow`'s `{:#}` shows, which
/// `results.json`'s failed policies have always carried).
fn with_sources(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text.push_str(": ");
        text.push_str(&s.to_string());
        source = s.source();
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("outer")]
    struct Outer(#[source] std::io::Error);

    #[test]
    fn an_error_is_shown_with_its_sources() {
        let e = Outer(std::io::Error::other("inner"));
        assert_eq!(with_sources(&e), "outer: inner");
    }
}
