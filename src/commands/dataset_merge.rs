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
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::replay::ReplayReader;

use crate::output::dataset::StagedDataset;
use serde_json::{Value, json};

use super::episodes::{BehaviourKind, Perturbation, behaviour_label};
use crate::progress;

/// Checks that `r` matches the first input in everything a consumer relies on.
fn check_compatible(first: &ReplayReader, r: &ReplayReader) -> Result<()> {
    let (a, b) = (first.spec()?, r.spec()?);
    let name = r.path.display();
    if a.image_hw != b.image_hw {
        bail!("{name}: data/img is {:?}, {} has {:?}", b.image_hw, first.path.display(), a.image_hw);
    }
    if a.action_dim != b.action_dim || a.state_dim != b.state_dim {
        bail!(
            "{name}: action/state dims {}/{} differ from {}'s {}/{}",
            b.action_dim,
            b.state_dim,
            first.path.display(),
            a.action_dim,
            a.state_dim
        );
    }
    if a.extras != b.extras {
        bail!("{name}: extra arrays {:?} differ from {}'s {:?}", b.extras, first.path.display(), a.extras);
    }
    let (ea, eb) = (&first.attrs["evalharness"], &r.attrs["evalharness"]);
    for field in ["scenario", "scenario_config", "state_columns"] {
        if ea[field] != eb[field] {
            bail!("{name}: attribute evalharness.{field} differs from {}'s", first.path.display());
        }
    }
    Ok(())
}

/// An input's episode attributes, relabelled and tagged with their source index.
fn episode_attrs(r: &ReplayReader, source: usize) -> Vec<Value> {
    let e = &r.attrs["evalharness"];
    let p = Perturbation {
        noise: e["noise"].as_f64().unwrap_or(0.0),
        lag: e["lag"].as_u64().unwrap_or(0) as usize,
    };
    let listed = e["episodes"].as_array().filter(|l| l.len() == r.episodes());
    (0..r.episodes())
        .map(|i| {
            let mut ep = listed.map_or_else(|| json!({}), |l| l[i].clone());
            if ep["behaviour"] == "expert" {
                ep["behaviour"] = json!(behaviour_label(BehaviourKind::Expert, p));
            }
            ep["source"] = json!(source);
            ep
        })
        .collect()
}

/// Runs the command.
pub fn run(inputs: &[PathBuf], out: &Path, force: bool, quiet: bool) -> Result<ExitCode> {
    if inputs.len() < 2 {
        bail!("dataset merge needs at least two input datasets, got {}", inputs.len());
    }
    let listed = crate::output::Inputs::new().all("dataset", inputs);
    // Inputs before outputs: checked before any dataset is opened or anything written.
    listed.refuse(out, ".partial")?;
    let readers = inputs
        .iter()
        .map(|p| ReplayReader::open(p).with_context(|| format!("opening dataset {}", p.display())))
        .collect::<Result<Vec<_>>>()?;
    for r in &readers[1..] {
        check_compatible(&readers[0], r)?;
    }
    let spec = readers[0].spec()?;
    let total: usize = readers.iter().map(ReplayReader::episodes).sum();
    let mut writer = StagedDataset::create(out, force, &listed, spec.clone())?;
    let pb = progress::bar(total as u64, "merge", quiet);
    let mut episodes = Vec::with_capacity(total);
    let mut sources = Vec::with_capacity(readers.len());
    for (k, r) in readers.iter().enumerate() {
        for i in 0..r.episodes() {
            let ep = r
                .read_episode(i, &spec.extras)
                .with_context(|| format!("reading episode {i} of {}", r.path.display()))?;
            writer.append(&ep)?;
            pb.inc(1);
        }
        episodes.extend(episode_attrs(r, k));
        let mut attrs = r.attrs["evalharness"].clone();
        if let Some(obj) = attrs.as_object_mut() {
            obj.remove("episodes");
        }
        sources.push(json!({"path": r.path.display().to_string(), "episodes": r.episodes(), "attrs": attrs}));
    }
    pb.finish_and_clear();
    let first = &readers[0].attrs["evalharness"];
    let mut attrs = json!({
        "version": env!("CARGO_PKG_VERSION"),
        "merged_from": sources,
        "episodes": episodes,
    });
    for field in ["scenario", "scenario_config", "state_columns", "action", "coverage"] {
        if !first[field].is_null() {
            attrs[field] = first[field].clone();
        }
    }
    let path = writer.finish(&json!({ "evalharness": attrs }))?;
    let steps: usize = readers.iter().map(ReplayReader::steps).sum();
    outln!("merged {} datasets: {total} episodes, {steps} steps -> {}", readers.len(), path.display());
    Ok(ExitCode::SUCCESS)
}
