//! A judge run's resumable state, in its `.train/` folder, kept the way every other
//! trainer keeps its own ([`harness::runfile`], [`harness::checkpoint`], [`harness::driver`]):
//! - `config.json`: the judge as it will be written (network, label, threshold,
//!   persistence, provenance) and the training settings. A resumed run keeps it, except
//!   for its length, which `--steps` may change;
//! - the checkpoint: `model.bpk` and `optimizer.bpk` (full precision) and `state.json`
//!   (step, training seconds over all sessions), staged and committed as one unit by a
//!   manifest, written at every evaluation and when a session ends, and recovered before a
//!   resume.
//!
//! A resumed run draws the batches an uninterrupted one would (each step's from
//! `(seed, step)`) from the optimiser state it had, so it ends with the same weights.

use std::path::Path;

use burn::module::Module;
use burn::optim::ModuleOptimizer;
use harness::checkpoint::{MAIN, begin, recover};
use serde::{Deserialize, Serialize};

use crate::error::JudgeError;
use crate::folder::{JudgeFile, JudgeNet};
use crate::provenance::JudgeTrainConfig;

/// A judge run's `.train/config.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JudgeRunConfig {
    /// The judge as it will be written; its metrics and steps are filled in when a
    /// session ends.
    pub judge: JudgeFile,
    /// The training settings.
    pub train: JudgeTrainConfig,
}

pub(crate) use harness::driver::State;

/// The configuration of the run whose `.train` folder is `dir`: `fresh`, written there, for
/// a new run; the saved one when resuming, with `steps` (when given) as its step total.
///
/// # Errors
/// [`JudgeError::Write`] naming the file when it cannot be written or, when resuming, is
/// missing or is not a judge run's.
pub fn resume_or_start(
    dir: &Path,
    fresh: JudgeRunConfig,
    resume: bool,
    steps: Option<u64>,
) -> Result<JudgeRunConfig, JudgeError> {
    Ok(harness::runfile::resume_or_start(
        &dir.join("config.json"),
        fresh,
        resume,
        |c: &mut JudgeRunConfig| {
            let changed = steps.is_some_and(|s| s != c.train.steps);
            if let Some(s) = steps {
                c.train.steps = s;
            }
            changed
        },
    )?)
}

/// Saves the checkpoint of step `state.step` into `dir`.
///
/// # Errors
/// [`JudgeError`] naming the file that could not be written.
pub(crate) fn save(
    dir: &Path,
    net: &JudgeNet,
    optim: &ModuleOptimizer,
    state: State,
) -> Result<(), JudgeError> {
    let mut stage = begin(dir, MAIN)?;
    let [model, optimizer, state_file] = ["model.bpk", "optimizer.bpk", "state.json"].map(|n| stage.path(n));
    net.clone().save_file(&model).map_err(|source| JudgeError::Weights { path: model, source })?;
    optim.save(&optimizer).map_err(|source| JudgeError::Weights { path: optimizer, source })?;
    harness::driver::write_state(&state_file, &state)?;
    Ok(stage.commit()?)
}

/// The checkpoint in `dir` (recovered first if a save was cut short), loaded into `net`
/// and `optim`. A checkpoint of step 0 holds no training, and a resume from it starts as a
/// fresh run does, from `net` as created: burn draws a parameter's initial values when it is
/// first read, so the weights a step-0 save wrote (read in the order the file lists them)
/// are not the ones the first training step reads (in the order the forward pass does).
///
/// # Errors
/// [`JudgeError`] naming the file that is missing, truncated or does not fit.
pub(crate) fn load(
    dir: &Path,
    net: JudgeNet,
    optim: ModuleOptimizer,
) -> Result<(JudgeNet, ModuleOptimizer, State), JudgeError> {
    recover(dir, MAIN)?;
    let [model, optimizer, state_file] = ["model.bpk", "optimizer.bpk", "state.json"].map(|n| dir.join(n));
    let state: State = harness::driver::read_state(&state_file)?;
    if state.step == 0 {
        return Ok((net, optim, state));
    }
    let net = net.try_load_file(&model).map_err(|source| JudgeError::Weights { path: model, source })?;
    let optim = optim.load(&optimizer).map_err(|source| JudgeError::Weights { path: optimizer, source })?;
    Ok((net, optim, state))
}
