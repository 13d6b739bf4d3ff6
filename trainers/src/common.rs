//! What the four training commands share: the task and the recipe of a dataset, the run
//! folder prepared before training (inputs checked, `--resume` and `--force`), the flags a
//! `--resume` may not change, and the provenance's `data` entry.

use harness::provenance::FramesUsed;
use harness::replay::attrs::{DatasetAttrs, Recipe};

use crate::error::{Context, Result, refuse};

/// The task a dataset was collected in ([`harness::replay::origin`]: its attributes name
/// it; another codebase's Push-T replay buffer has none).
///
/// # Errors
/// A dataset whose attributes cannot be read or name no task, or a task this build
/// cannot load.
pub(crate) fn dataset_task(data: &std::path::Path) -> Result<Box<dyn harness::task::Task>> {
    let scenario = harness::replay::origin::scenario_of(data)?;
    scenarios::load_task(&scenario).with_context(|| format!("{}: its task {scenario}", data.display()))
}

/// How an evalharness dataset was collected (from its attributes), to regenerate it:
/// `collect` is deterministic, so the same arguments give the same bytes. A merged
/// dataset lists the recipe of each of its inputs, in order. `None` for a dataset
/// evalharness did not make.
///
/// # Errors
/// A dataset whose attributes cannot be read (never taken for one without them).
pub(crate) fn dataset_origin(data: &std::path::Path) -> Result<Option<Recipe>> {
    let attrs = harness::zarr::read_attrs(data)?;
    Ok(DatasetAttrs::from_root(data, &attrs)?.map(|a| a.recipe(None)))
}

/// A setting `--resume` cannot change: the flag's clap id, the value this command
/// line gives it and the run's saved value.
pub(crate) type FixedFlag = (&'static str, serde_json::Value, serde_json::Value);

/// The flag `id`'s value on this command line and in the saved run, as JSON (how the
/// refusal shows the saved one).
pub(crate) fn fixed<T: serde::Serialize>(id: &'static str, fresh: &T, saved: &T) -> FixedFlag {
    let json = |v: &T| serde_json::to_value(v).unwrap_or_default();
    (id, json(fresh), json(saved))
}

/// `--resume` continues a run with the settings saved in `saved` (its config file).
/// A flag typed on this command line (`given`: the ids of the flags typed) whose value
/// differs from the saved one would be silently ignored, so the run is refused, naming
/// each such flag with its saved value (flags left at their defaults are not compared).
pub(crate) fn refuse_contradicting_flags(
    saved: &std::path::Path,
    given: &[String],
    fixed: &[FixedFlag],
) -> Result<()> {
    let conflicts: Vec<String> = fixed
        .iter()
        .filter(|(id, ours, theirs)| given.iter().any(|g| g == id) && ours != theirs)
        .map(|(id, _, theirs)| format!("--{} (saved: {theirs})", id.replace('_', "-")))
        .collect();
    if conflicts.is_empty() {
        return Ok(());
    }
    refuse!(
        "--resume continues the run with the settings saved in {}, which {} contradict: {}; \
         drop them, or start a new run",
        saved.display(),
        if conflicts.len() == 1 { "this flag would" } else { "these flags would" },
        conflicts.join(", ")
    )
}

/// Checks a training run's inputs and output folder, then prepares it: an existing
/// one needs `--resume` (and then its checkpoint, `state` relative to it) or `--force`
/// (which moves it aside until the new run completes, see
/// [`runner::output::RunDir`]). Each input (with its flag) must exist and lie apart
/// from the output.
pub(crate) fn prepare_out(
    out: &std::path::Path,
    resume: bool,
    force: bool,
    state: &'static str,
    inputs: &[(&str, &std::path::Path)],
) -> Result<runner::output::RunDir> {
    for (flag, p) in inputs {
        if !p.exists() {
            refuse!("{flag} {}: no such file or folder", p.display());
        }
    }
    let listed = inputs.iter().fold(runner::output::Inputs::new(), |acc, (f, p)| acc.add(f, p));
    listed.check(out)?;
    if resume && !out.join(state).is_file() {
        refuse!("--resume: {} has no checkpoint ({state})", out.display());
    }
    Ok(runner::output::RunDir::prepare(out, &listed, resume, force, state)?)
}

/// The `data` entry of a world-model or autoencoder provenance file.
///
/// # Errors
/// A dataset whose attributes cannot be read.
pub fn data_provenance(path: &std::path::Path, episodes: usize, frames: usize) -> Result<FramesUsed> {
    Ok(FramesUsed::new(path, episodes, frames, dataset_origin(path)?))
}
