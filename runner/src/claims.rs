//! `rank --shard i/n --claims DIR`: shard processes that share the batches out as they
//! go instead of each taking every n-th one.
//!
//! Why: `rank --processes` splits a run into shard processes (Lift's and Can's renderer
//! lets one thread of a process render at a time). A fixed split gives each shard the
//! same number of batches, but not the same work: a policy that fails runs every
//! episode to the step limit, one that succeeds stops early, so on Can one shard ran
//! alone for the last minutes of a 35-minute run (BENCHMARKS.md, 2026-11-28). Here
//! every shard walks the batches in the same order and runs the next one no shard has
//! claimed, so the last batches go to whichever shards are free.
//!
//! A claim is a file `DIR/policy-P-batch-B` holding the shard's index, created only
//! if it does not exist (`O_EXCL`, which any local file system honours). A shard that
//! is resumed or restarted takes its own claims back; its rows say which of them it
//! finished. (A shard killed between creating a claim and writing its index leaves a
//! claim nobody takes back: the joined run runs that batch.) The rows do not depend
//! on which shard ran a batch (a batch's rows are a pure function of it), and the
//! joined run runs any batch no shard finished, so a lost claim costs time, never a
//! row.

use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};

use engine::schedule::{self, Batch, BatchResult};
use engine::{EngineError, Setup, Timing};
use world_model::model::WorldModel;

use crate::error::RunError;

/// One shard's hold on a claims folder.
pub struct Claims {
    dir: PathBuf,
    shard: usize,
}

impl Claims {
    /// Opens (creating it if needed) the claims folder `dir` for shard `shard`.
    ///
    /// # Errors
    /// A folder that cannot be created, naming it.
    pub fn open(dir: &Path, shard: usize) -> Result<Self, RunError> {
        std::fs::create_dir_all(dir)
            .map_err(RunError::file(format!("creating the claims folder {}", dir.display())))?;
        Ok(Self { dir: dir.to_path_buf(), shard })
    }

    /// The claim file's name of batch `batch` of policy `policy` (indices in the run's
    /// checkpoint and batch order, which every shard of a run shares).
    pub fn key(policy: usize, batch: usize) -> String {
        format!("policy-{policy}-batch-{batch}")
    }

    /// Whether this shard runs batch `key`: it claims it now, or claimed it before (a
    /// resumed or restarted shard finishes its own). False when another shard has it.
    ///
    /// # Errors
    /// A claim that cannot be written or read, naming the file.
    pub fn take(&self, key: &str) -> Result<bool, RunError> {
        let path = self.dir.join(key);
        let mine = self.shard.to_string();
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(mut f) => {
                f.write_all(mine.as_bytes())
                    .map_err(RunError::file(format!("writing the claim {}", path.display())))?;
                Ok(true)
            }
            Err(e) if e.kind() == ErrorKind::AlreadyExists => {
                let owner = std::fs::read_to_string(&path)
                    .map_err(RunError::file(format!("reading the claim {}", path.display())))?;
                Ok(owner == mine)
            }
            Err(e) => Err(RunError::file(format!("claiming {}", path.display()))(e)),
        }
    }
}

/// Runs the batches of `jobs` this shard claims, one at a time on one worker (a shard
/// process has one), calling `done(index into jobs, result)` in job order; `keys[j]` is
/// job j's claim. A policy whose batch fails has its later batches left, as
/// [`schedule::run_batches`] leaves them. Returns the summed timing.
///
/// # Errors
/// A claim that cannot be made, or what `done` or the scheduler return.
pub fn run_claimed<E: From<EngineError> + From<RunError>>(
    policies: &[&dyn harness::policy::Policy],
    jobs: &[Batch],
    keys: &[String],
    claims: &Claims,
    setup: &Setup,
    wm: &WorldModel,
    done: &mut dyn FnMut(usize, BatchResult) -> Result<(), E>,
) -> Result<Timing, E> {
    let mut failed = vec![false; policies.len()];
    let mut total = Timing::default();
    for (j, job) in jobs.iter().enumerate() {
        if failed[job.policy] || !claims.take(&keys[j])? {
            continue;
        }
        let mut one = |_: usize, out: BatchResult| {
            failed[job.policy] |= out.is_err();
            done(j, out)
        };
        let t = schedule::run_batches::<E>(policies, std::slice::from_ref(job), setup, wm, 1, &mut one)?;
        total.add(&t);
    }
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_goes_to_the_first_shard_that_claims_it_and_back_to_it_on_resume() {
        let dir = tempfile::tempdir().unwrap();
        let claims = dir.path().join("claims");
        let (a, b) = (Claims::open(&claims, 0).unwrap(), Claims::open(&claims, 1).unwrap());
        let key = Claims::key(2, 3);
        assert_eq!(key, "policy-2-batch-3");
        assert!(a.take(&key).unwrap(), "a fresh batch is claimed");
        assert!(!b.take(&key).unwrap(), "another shard's batch is left");
        assert!(a.take(&key).unwrap(), "a resumed shard takes its own claim back");
        assert!(b.take(&Claims::key(2, 4)).unwrap());
        assert_eq!(std::fs::read_to_string(claims.join(&key)).unwrap(), "0");
        let mut names: Vec<String> = std::fs::read_dir(&claims)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        assert_eq!(names, ["policy-2-batch-3", "policy-2-batch-4"]);
        // Shard 10 is not shard 1: the whole index is compared.
        assert!(!Claims::open(&claims, 10).unwrap().take(&Claims::key(2, 4)).unwrap());
    }

    #[test]
    fn a_claims_folder_that_cannot_be_made_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("f");
        std::fs::write(&file, "").unwrap();
        let e = Claims::open(&file.join("claims"), 0).err().unwrap();
        assert!(format!("{e:#}").contains(&file.join("claims").display().to_string()), "{e:#}");
    }
}
