//! `evalharness export-policies`: assembles a policy set from diffusion-policy
//! checkpoints — typically chosen epochs of one `train policy` run — optionally
//! with other inference settings (executed actions per decision, DDIM steps).
//!
//! `--add` puts the checkpoints into an existing set (e.g. a fine-tuning run's
//! epochs, `--prefix ft-`, next to the run it started from).
//!
//! Weights are copied byte for byte; `policy.json` keeps everything but the
//! changed settings and appends to `provenance.exported` (command, commit, source
//! folder, each change as `[before, after]`; one entry per export, oldest first). A checkpoint's `provenance.json`
//! (its measured MuJoCo score) is carried over only when no inference setting
//! changed: a score measured with other settings would be wrong for the copy.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::provenance::Exported;
use policies::diffusion::DiffusionConfig;
use policies::dir::{PolicyFile, checkpoint_dirs};
use policies::provenance::PolicyScores;

use super::git_commit;
use crate::cli::ExportPoliciesArgs;
use crate::output::{Staged, write_json};

/// A checkpoint to export: its folder, file and the settings changed.
struct Export {
    dir: PathBuf,
    name: String,
    file: PolicyFile,
    changes: BTreeMap<String, [usize; 2]>,
}

/// `evalharness export-policies`.
pub fn run(a: &ExportPoliciesArgs) -> Result<ExitCode> {
    let mut picked = Vec::new();
    for dir in checkpoint_dirs(&a.from)? {
        let file = read_policy(&dir)?;
        if a.epochs.is_empty() || a.epochs.contains(&file.epoch) {
            picked.push(prepare(&dir, file, a)?);
        }
    }
    let missing: Vec<String> =
        a.epochs.iter().filter(|e| !picked.iter().any(|p| p.file.epoch == **e)).map(u64::to_string).collect();
    if !missing.is_empty() {
        bail!("{}: no checkpoint of epoch {}", a.from.display(), missing.join(", "));
    }
    if a.add && !a.out.is_dir() {
        bail!("--add: {} is not an existing policy set", a.out.display());
    }
    if a.prefix.contains(['/', '\\']) || a.prefix.starts_with('.') {
        bail!(
            "--prefix {:?}: a folder-name prefix cannot contain a path separator or start with '.'",
            a.prefix
        );
    }
    let taken: Vec<&str> =
        picked.iter().filter(|p| a.add && a.out.join(&p.name).exists()).map(|p| p.name.as_str()).collect();
    if !taken.is_empty() {
        bail!("--add: {} already holds {}", a.out.display(), taken.join(", "));
    }
    // `--add` moves new checkpoints into `--out`, so only plain replacing must stay
    // apart from `--from`.
    // With --add the output is the folder being added to, which may hold --from.
    let inputs = if a.add {
        crate::output::Inputs::new()
    } else {
        crate::output::Inputs::new().add("--from", &a.from)
    };
    let out = Staged::new(&a.out, a.force || a.add, &inputs)?;
    let command: Vec<String> = crate::stdout::command_line();
    let (command, commit) = (command.join(" "), git_commit());
    for p in &mut picked {
        let dst = out.file(&p.name);
        std::fs::create_dir_all(&dst).with_context(|| format!("creating {}", dst.display()))?;
        let (from, to) = (p.dir.join("model.bpk"), dst.join("model.bpk"));
        std::fs::copy(&from, &to)
            .with_context(|| format!("copying {} to {}", from.display(), to.display()))?;
        let exported = Exported {
            alpha: None,
            changed: Some(p.changes.clone()),
            command: command.clone(),
            commit: commit.clone(),
            from: p.dir.display().to_string(),
            other: BTreeMap::new(),
        };
        p.file.provenance.exported.push(exported.clone());
        write_json(&dst.join("policy.json"), &p.file)?;
        let scores = p.dir.join("provenance.json");
        if p.changes.is_empty() && scores.is_file() {
            let mut v: PolicyScores = harness::provenance::read(&scores)?;
            v.training.exported.push(exported);
            write_json(&dst.join("provenance.json"), &v)?;
        }
    }
    let root = if a.add { out.commit_into()? } else { out.commit()? };
    for p in &picked {
        outln!("{}", root.join(&p.name).display());
    }
    Ok(ExitCode::SUCCESS)
}

/// Checks the kind and applies the requested settings to `file`'s config.
fn prepare(dir: &Path, mut file: PolicyFile, a: &ExportPoliciesArgs) -> Result<Export> {
    let path = dir.join("policy.json");
    let mut cfg: DiffusionConfig = serde_json::from_value(file.config.clone())
        .with_context(|| format!("{}: \"config\"", path.display()))?;
    let mut changes = BTreeMap::new();
    if let Some(k) = a.action_horizon.filter(|&k| k != cfg.action_horizon) {
        changes.insert("action_horizon".into(), [cfg.action_horizon, k]);
        cfg.action_horizon = k;
    }
    if let Some(s) = a.inference_steps.filter(|&s| s != cfg.inference_steps) {
        changes.insert("inference_steps".into(), [cfg.inference_steps, s]);
        cfg.inference_steps = s;
    }
    let room = cfg.max_action_horizon();
    if cfg.action_horizon == 0 || cfg.action_horizon > room {
        bail!(
            "{}: --action-horizon {} must be 1..={room} (horizon {} minus obs horizon {} plus 1)",
            dir.display(),
            cfg.action_horizon,
            cfg.horizon,
            cfg.net.obs_horizon
        );
    }
    if cfg.inference_steps == 0 || cfg.inference_steps > cfg.train_steps {
        bail!(
            "{}: --inference-steps {} must be 1..={} (the training schedule's steps)",
            dir.display(),
            cfg.inference_steps,
            cfg.train_steps
        );
    }
    file.config = serde_json::to_value(&cfg)?;
    let name = dir
        .file_name()
        .map_or_else(|| format!("epoch-{:04}", file.epoch), |n| n.to_string_lossy().into_owned());
    let name = format!("{}{name}", a.prefix);
    Ok(Export { dir: dir.to_path_buf(), name, file, changes })
}

/// A diffusion checkpoint's `policy.json` (other kinds are named and refused).
fn read_policy(dir: &Path) -> Result<PolicyFile> {
    let path = dir.join("policy.json");
    match policies::dir::policy_kind(dir) {
        Some(k) if k == "diffusion" => {}
        k => bail!(
            "{}: kind {}: only diffusion checkpoints are exported",
            path.display(),
            k.map_or_else(|| "(none)".to_string(), |k| format!("{k:?}"))
        ),
    }
    policies::dir::read_policy_file(dir)
        .with_context(|| format!("{}: not a diffusion policy file", path.display()))
}
