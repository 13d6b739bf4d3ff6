//! Output directories that never look complete before they are.
//!
//! A command writes into `OUT.partial/` and renames it to `OUT` at the end; an
//! existing `OUT` is refused unless `--force`. A resumable run ([`RunDir`]) writes
//! in place, and moves a folder it replaces aside until it completes.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// A run's output folder that `--resume` can continue, guarded so that a failed or
/// refused run never costs the user a finished result (the guarantees in
/// `docs/guarantees.md`):
/// - an existing folder is kept with `--resume`, and refused without `--resume` or
///   `--force`;
/// - with `--force`, the old folder is renamed to `OUT.replaced` (not deleted) and
///   the new run writes a fresh `OUT`; only [`RunDir::finish`] of a complete run
///   deletes `OUT.replaced`. A run that fails puts the old folder back and drops
///   its own; a killed one leaves both, and `--resume` continues the new one;
/// - a folder this run created is removed again when the run fails before writing
///   its progress file (rows or a checkpoint), so a corrected rerun is not blocked.
pub struct RunDir {
    out: PathBuf,
    aside: Option<PathBuf>,
    created: bool,
    progress: &'static str,
    settled: bool,
}

impl RunDir {
    /// Prepares `out`; call it only after every input has been checked.
    /// `progress` names the file whose presence means the run has something to keep
    /// (e.g. `episodes.jsonl`, `state.json`).
    ///
    /// # Errors
    /// An existing folder without `resume` or `force`, an `OUT.replaced` left by an
    /// interrupted `--force` run, or a failure to rename or create a folder.
    pub fn prepare(out: &Path, resume: bool, force: bool, progress: &'static str) -> Result<Self> {
        let aside = sibling(out, ".replaced");
        let mut dir = Self { out: out.to_path_buf(), aside: None, created: false, progress, settled: false };
        if resume {
            // A resumed `--force` run completes the replacement when it finishes.
            dir.aside = aside.exists().then_some(aside);
        } else if out.exists() {
            if !force {
                bail!(
                    "{} already exists (pass --resume to continue it or --force to replace it)",
                    out.display()
                );
            }
            if aside.exists() {
                bail!(
                    "{} holds the run an interrupted --force run was replacing; move it back to {} \
                     (or delete it) before replacing {} again, or pass --resume to continue the new run",
                    aside.display(),
                    out.display(),
                    out.display()
                );
            }
            std::fs::rename(out, &aside)
                .with_context(|| format!("moving {} aside to {}", out.display(), aside.display()))?;
            dir.aside = Some(aside);
        }
        if !dir.out.exists() {
            dir.created = true;
            std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
        }
        Ok(dir)
    }

    /// [`RunDir::prepare`] for a run that appends its rows to `episodes.jsonl` beside
    /// the `config.json` they were run with (`rank`, `plan`): rows without that
    /// config cannot be checked against the settings, so resuming them is refused.
    ///
    /// # Errors
    /// As [`RunDir::prepare`], and rows without a `config.json` on `--resume`.
    pub fn prepare_episodes(out: &Path, resume: bool, force: bool) -> Result<Self> {
        if resume && out.join("episodes.jsonl").exists() && !out.join("config.json").is_file() {
            bail!(
                "--resume: {} has episodes but no config.json, so the settings its rows were run with \
                 are unknown; start a new run (--force or another --out)",
                out.display()
            );
        }
        Self::prepare(out, resume, force, "episodes.jsonl")
    }

    /// The run ended: a `complete` run deletes the folder it replaced; an incomplete
    /// one (stopped early, resumable) keeps it, saying where.
    ///
    /// # Errors
    /// A failure to delete the replaced folder.
    pub fn finish(mut self, complete: bool) -> Result<()> {
        self.settled = true;
        match (&self.aside, complete) {
            (Some(aside), true) => std::fs::remove_dir_all(aside)
                .with_context(|| format!("removing the replaced run {}", aside.display())),
            (Some(aside), false) => {
                tracing::warn!(
                    "the run this one replaces stays in {} until it completes (--resume)",
                    aside.display()
                );
                Ok(())
            }
            (None, _) => Ok(()),
        }
    }
}

impl Drop for RunDir {
    /// The run failed: put back what it replaced, or remove a folder it created and
    /// wrote nothing worth keeping into.
    fn drop(&mut self) {
        if self.settled {
            return;
        }
        if let Some(aside) = &self.aside {
            let restored =
                std::fs::remove_dir_all(&self.out).and_then(|()| std::fs::rename(aside, &self.out));
            match restored {
                Ok(()) => tracing::warn!("the run failed; {} is as it was before", self.out.display()),
                Err(e) => tracing::error!(
                    "the run failed and {} could not be put back from {}: {e}",
                    self.out.display(),
                    aside.display()
                ),
            }
        } else if self.created && !has_content(&self.out.join(self.progress)) {
            let _ = std::fs::remove_dir_all(&self.out);
        }
    }
}

/// Whether `path` is a non-empty file.
fn has_content(path: &Path) -> bool {
    std::fs::metadata(path).is_ok_and(|m| m.len() > 0)
}

/// `path` with `suffix` appended to its last component (`out` -> `out.replaced`).
fn sibling(path: &Path, suffix: &str) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(suffix);
    PathBuf::from(s)
}

/// Refuses an output folder that is, lies inside, or contains one of the inputs
/// (each given with the flag that named it): replacing it would delete the input,
/// and an output inside a policy folder would be loaded as a policy next time.
///
/// # Errors
/// The first overlap, naming the flag and both paths.
pub fn check_apart(out: &Path, inputs: &[(&str, &Path)]) -> Result<()> {
    let o = absolute(out);
    for (flag, input) in inputs {
        let i = absolute(input);
        let how = if o == i {
            "is"
        } else if o.starts_with(&i) {
            "lies inside"
        } else if i.starts_with(&o) {
            "contains"
        } else {
            continue;
        };
        bail!(
            "--out {} {how} the input {flag} {}; write the output somewhere else",
            out.display(),
            input.display()
        );
    }
    Ok(())
}

/// `p` as an absolute path with its existing part resolved (symbolic links, `..`),
/// so two spellings of one folder compare equal even when `p` does not exist yet.
fn absolute(p: &Path) -> PathBuf {
    let p = std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let mut tail = Vec::new();
    let mut head = p.as_path();
    loop {
        if let Ok(real) = head.canonicalize() {
            return tail.iter().rev().fold(real, |acc, c| acc.join(c));
        }
        match (head.parent(), head.file_name()) {
            (Some(parent), Some(name)) => {
                tail.push(name.to_os_string());
                head = parent;
            }
            _ => return p,
        }
    }
}

/// A staging directory for an output folder.
pub struct Staged {
    target: PathBuf,
    tmp: PathBuf,
}

impl Staged {
    /// Prepares `target` (refusing an existing one unless `force`).
    pub fn new(target: &Path, force: bool) -> Result<Self> {
        if target.exists() && !force {
            bail!("output {} already exists (pass --force to replace it)", target.display());
        }
        let tmp = sibling(target, ".partial");
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).with_context(|| format!("removing stale {}", tmp.display()))?;
        }
        std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
        Ok(Self { target: target.to_path_buf(), tmp })
    }

    /// The staging directory itself.
    pub fn dir(&self) -> &Path {
        &self.tmp
    }

    /// Path of `name` inside the staging directory.
    pub fn file(&self, name: &str) -> PathBuf {
        self.tmp.join(name)
    }

    /// Moves the staging directory into place (replacing an old output).
    pub fn commit(self) -> Result<PathBuf> {
        if self.target.exists() {
            std::fs::remove_dir_all(&self.target)
                .with_context(|| format!("removing old {}", self.target.display()))?;
        }
        std::fs::rename(&self.tmp, &self.target)
            .with_context(|| format!("moving {} into place", self.target.display()))?;
        Ok(self.target.clone())
    }

    /// Moves each entry of the staging directory into the existing target folder,
    /// refusing (before moving anything) names the target already holds.
    pub fn commit_into(self) -> Result<PathBuf> {
        let entries: Vec<PathBuf> = std::fs::read_dir(&self.tmp)
            .with_context(|| format!("reading {}", self.tmp.display()))?
            .map(|e| e.map(|e| e.path()))
            .collect::<std::io::Result<_>>()
            .with_context(|| format!("reading {}", self.tmp.display()))?;
        let taken: Vec<String> = entries
            .iter()
            .filter_map(|e| e.file_name())
            .filter(|n| self.target.join(n).exists())
            .map(|n| n.to_string_lossy().into_owned())
            .collect();
        if !taken.is_empty() {
            std::fs::remove_dir_all(&self.tmp).with_context(|| format!("removing {}", self.tmp.display()))?;
            bail!("{} already holds {}", self.target.display(), taken.join(", "));
        }
        for e in &entries {
            let dst = self.target.join(e.file_name().unwrap_or_default());
            std::fs::rename(e, &dst)
                .with_context(|| format!("moving {} to {}", e.display(), dst.display()))?;
        }
        std::fs::remove_dir(&self.tmp).with_context(|| format!("removing {}", self.tmp.display()))?;
        Ok(self.target.clone())
    }
}

impl Drop for Staged {
    /// A command that fails before [`Staged::commit`] leaves no `OUT.partial` behind.
    fn drop(&mut self) {
        if self.tmp.exists() {
            let _ = std::fs::remove_dir_all(&self.tmp);
        }
    }
}

/// Reads a JSON file, naming it in any error.
pub fn read_json(path: &Path) -> Result<serde_json::Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", path.display()))
}

/// Writes pretty JSON to a file.
pub fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let mut text = serde_json::to_string_pretty(value)?;
    text.push('\n');
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
