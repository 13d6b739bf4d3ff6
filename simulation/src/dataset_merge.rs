//! `evalharness dataset merge`: one dataset from several, episodes in argument order.
//!
//! A world model needs more varied data than one `collect` call gives (clean
//! experts, noisy experts, exploration, each with its own `--noise`/`--lag`), so
//! such collections are merged into one training set. The inputs must agree on
//! image size, action and state dimensions, per-step extras and scenario
//! configuration; the first disagreement is an error naming the file and field.
//! Every episode keeps its recorded attributes (seed, behaviour, score) plus
//! `source` (the input's index). An expert collected with noise or lag is
//! relabelled as such (`expert+noise80`) when its input predates that label, so
//! the policy trainer's `--behaviour expert` keeps selecting clean demonstrations.
//! The inputs' attributes minus their episode lists are kept under `merged_from`,
//! which is how provenance regenerates each part.

use std::path::{Path, PathBuf};

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use harness::replay::ReplayReader;
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, MergedPart};

use runner::output::dataset::StagedDataset;

use scenarios::pusht::runs::{BehaviourKind, Perturbation, behaviour_label};

/// An input's evalharness attributes (none for a dataset without them).
fn attrs_of(r: &ReplayReader) -> Result<Option<DatasetAttrs>> {
    Ok(DatasetAttrs::from_root(&r.path, &r.attrs)?)
}

/// Checks that `r` (with attributes `eb`) matches the first input (`ea`) in everything a
/// consumer relies on.
fn check_compatible(
    (first, ea): (&ReplayReader, &DatasetAttrs),
    (r, eb): (&ReplayReader, &DatasetAttrs),
) -> Result<()> {
    let (a, b) = (first.spec()?, r.spec()?);
    let name = r.path.display();
    if a.image_hw != b.image_hw {
        refuse!("{name}: data/img is {:?}, {} has {:?}", b.image_hw, first.path.display(), a.image_hw);
    }
    if a.action_dim != b.action_dim || a.state_dim != b.state_dim {
        refuse!(
            "{name}: action/state dims {}/{} differ from {}'s {}/{}",
            b.action_dim,
            b.state_dim,
            first.path.display(),
            a.action_dim,
            a.state_dim
        );
    }
    if a.extras != b.extras {
        refuse!("{name}: extra arrays {:?} differ from {}'s {:?}", b.extras, first.path.display(), a.extras);
    }
    let differs = [
        ("scenario", ea.scenario != eb.scenario),
        ("scenario_config", recorded_config(ea) != recorded_config(eb)),
        ("state_columns", ea.state_columns != eb.state_columns),
    ];
    if let Some((field, _)) = differs.iter().find(|(_, d)| *d) {
        refuse!("{name}: attribute evalharness.{field} differs from {}'s", first.path.display());
    }
    Ok(())
}

/// An input's task configuration with its rendering written out (a Lift or Can dataset
/// collected before 2026-12-03 left robosuite's rendering implicit), as inputs are compared and
/// the merged dataset records it.
fn recorded_config(a: &DatasetAttrs) -> Option<serde_json::Value> {
    let scenario = a.scenario.as_deref().unwrap_or_default();
    a.scenario_config.as_ref().map(|c| scenarios::recorded_config(scenario, c))
}

/// An input's episode attributes (`e`, of the input `r`), relabelled and tagged with their
/// source index.
fn episode_attrs(r: &ReplayReader, e: &DatasetAttrs, source: usize) -> Vec<EpisodeEntry> {
    let p = Perturbation { noise: e.source.noise.unwrap_or(0.0), lag: e.source.lag.unwrap_or(0) as usize };
    let listed = Some(&e.episodes).filter(|l| l.len() == r.episodes());
    (0..r.episodes())
        .map(|i| {
            let mut ep = listed.map_or_else(EpisodeEntry::default, |l| l[i].clone());
            if ep.behaviour.as_deref() == Some("expert") {
                ep.behaviour = Some(behaviour_label(BehaviourKind::Expert, p));
            }
            ep.source = Some(source as u64);
            ep
        })
        .collect()
}

/// Runs the command.
pub fn run(
    inputs: &[PathBuf],
    out: &Path,
    force: bool,
    inv: &Invocation,
    say: &mut dyn FnMut(&str),
) -> Result<bool> {
    if inputs.len() < 2 {
        refuse!("dataset merge needs at least two input datasets, got {}", inputs.len());
    }
    let listed = runner::output::Inputs::new().all("dataset", inputs);
    // Inputs before outputs: checked before any dataset is opened or anything written.
    listed.refuse(out, ".partial")?;
    let readers = inputs
        .iter()
        .map(|p| ReplayReader::open(p).with_context(|| format!("opening dataset {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    // Each input's attributes, read once (none for a dataset without them).
    let all = readers.iter().map(attrs_of).collect::<Result<Vec<_>>>()?;
    let none = DatasetAttrs::default();
    let first = all[0].as_ref().unwrap_or(&none);
    for (r, a) in readers.iter().zip(&all).skip(1) {
        check_compatible((&readers[0], first), (r, a.as_ref().unwrap_or(&none)))?;
    }
    // The merged dataset describes its arrays as the first input does.
    let header = DatasetAttrs {
        scenario: first.scenario.clone(),
        scenario_config: recorded_config(first),
        state_columns: first.state_columns.clone(),
        action: first.action.clone(),
        coverage: first.coverage.clone(),
        ..DatasetAttrs::new()
    };
    let spec = readers[0].spec()?;
    let total: usize = readers.iter().map(ReplayReader::episodes).sum();
    let mut writer = StagedDataset::create(out, force, &listed, spec.clone())?;
    let pb = runner::progress::bar(total as u64, "merge", inv.quiet);
    let mut episodes = Vec::with_capacity(total);
    let mut sources = Vec::with_capacity(readers.len());
    for (k, (r, attrs)) in readers.iter().zip(all).enumerate() {
        for i in 0..r.episodes() {
            let ep = r
                .read_episode(i, &spec.extras)
                .with_context(|| format!("reading episode {i} of {}", r.path.display()))?;
            writer.append(&ep)?;
            pb.inc(1);
        }
        episodes.extend(episode_attrs(r, attrs.as_ref().unwrap_or(&none), k));
        let path = r.path.display().to_string();
        let attrs = attrs.map(|a| DatasetAttrs { episodes: Vec::new(), ..a });
        sources.push(MergedPart { path, episodes: r.episodes() as u64, attrs });
    }
    pb.finish_and_clear();
    let attrs = DatasetAttrs { merged_from: Some(sources), episodes, ..header };
    let path = writer.finish(&attrs)?;
    let steps: usize = readers.iter().map(ReplayReader::steps).sum();
    say!(say, "merged {} datasets: {total} episodes, {steps} steps -> {}", readers.len(), path.display());
    Ok(true)
}
