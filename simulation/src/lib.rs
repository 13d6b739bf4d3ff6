//! `evalharness simulate`, `collect` and `dataset`: a task's scripted behaviours and policy
//! checkpoints run in its reference simulator, written as runs (`simulate`) or as datasets in
//! the task's layout (`collect`, and `simulate --replay-imagined --record`), and datasets read
//! and joined (`dataset info`, `dataset merge`).
//!
//! The commands know no task: each reaches the task `--scenario` names through
//! `scenarios::load_task`, and its behaviours and dataset layout through
//! `harness::scripted::Scripted`. Policy checkpoints run through the paired engine's
//! simulator branch, exactly as `rank` runs them.
//!
//! Why a crate of its own: the binary only parses the command line and dispatches here,
//! handing over what it knows of the process ([`Invocation`]); the commands' logic, their
//! errors ([`error::SimError`]) and their tests live beside the libraries they drive.

pub mod args;
mod collect;
mod collect_policy;
mod dataset;
mod dataset_merge;
pub mod error;
mod record;
mod simulate;
mod simulate_policy;
mod simulate_replay;

pub use error::SimError;

pub(crate) use runner::say;

pub use runner::command::Invocation;

/// `evalharness simulate`: a scripted behaviour, or every checkpoint of a policy folder.
/// Returns whether every policy ran (a checkpoint that failed is reported and skipped).
///
/// # Errors
/// A refused flag or input, or what the task, the engine or the output folder report.
pub fn simulate(
    a: &args::SimulateArgs,
    inv: &Invocation,
    say: &mut dyn FnMut(&str),
) -> Result<bool, SimError> {
    simulate::run(a, inv, say)
}

/// `evalharness collect`: a dataset of scripted episodes, or with `--policy` of policy
/// checkpoints' closed-loop episodes.
///
/// # Errors
/// A refused flag or input, or what the task, the engine or the dataset writer report.
pub fn collect(a: &args::CollectArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<(), SimError> {
    match &a.policy {
        Some(dir) => collect_policy::run(a, dir, inv, say),
        None => collect::run(a, inv, say),
    }
    .map(|_| ())
}

/// `evalharness dataset info|merge`.
///
/// # Errors
/// An unreadable dataset, or inputs `merge` cannot join.
pub fn dataset(
    cmd: &args::DatasetCommand,
    inv: &Invocation,
    say: &mut dyn FnMut(&str),
) -> Result<(), SimError> {
    match cmd {
        args::DatasetCommand::Info { path, json } => dataset::info(path, *json, say),
        args::DatasetCommand::Merge { inputs, out, force } => {
            dataset_merge::run(inputs, out, *force, inv, say)
        }
    }
    .map(|_| ())
}
