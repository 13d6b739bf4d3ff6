//! Output directories that never look complete before they are.
//!
//! A command writes into `OUT.partial/` and renames it to `OUT` at the end; an
//! existing `OUT` is refused unless `--force`.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// Prepares a run's output folder that `--resume` can continue: an existing `out` is
/// kept with `resume`, replaced with `force`, refused otherwise; then created.
///
/// # Errors
/// An existing folder without either flag, or a failure to remove or create it.
pub fn run_dir(out: &Path, resume: bool, force: bool) -> Result<()> {
    if out.exists() && !resume {
        if !force {
            bail!("{} already exists (pass --resume to continue it or --force to replace it)", out.display());
        }
        std::fs::remove_dir_all(out).with_context(|| format!("removing {}", out.display()))?;
    }
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))
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
        let mut tmp = target.as_os_str().to_owned();
        tmp.push(".partial");
        let tmp = PathBuf::from(tmp);
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).with_context(|| format!("removing stale {}", tmp.display()))?;
        }
        std::fs::create_dir_all(&tmp).with_context(|| format!("creating {}", tmp.display()))?;
        Ok(Self { target: target.to_path_buf(), tmp })
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
        Ok(self.target)
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
        Ok(self.target)
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
