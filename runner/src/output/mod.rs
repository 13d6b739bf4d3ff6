//! Output directories that never look complete before they are, and never cost the
//! user an input or a finished result.
//!
//! A command writes into `OUT.partial/` and renames it to `OUT` at the end ([`Staged`]);
//! an existing `OUT` is refused unless `--force`. A resumable run ([`RunDir`]) writes
//! in place, and moves a folder it replaces aside until it completes. Both take the
//! command's [`Inputs`] and check them against `--out` before touching anything
//! ([`inputs`]), refuse a dangling `--out` link, and hold the output's lock ([`lock`])
//! while they write. What can go wrong is an [`OutputError`].

pub mod dataset;
pub mod error;
pub mod inputs;
pub mod lock;

use std::path::{Path, PathBuf};

pub use error::OutputError;
use error::io;
pub use inputs::Inputs;
use inputs::sibling;

type Result<T, E = OutputError> = std::result::Result<T, E>;

/// The file that marks a folder beside `--out` as the tool's own (`OUT.partial`,
/// `OUT.shards`): only a folder with it is ever cleared. A folder of the same name
/// without it is the user's, and the command is refused instead.
pub const OWNED_MARK: &str = ".evalharness-owned";

/// Makes `dir` (fresh) as a folder the tool owns; an existing `dir` is removed first
/// only when it carries [`OWNED_MARK`] (`what` says what it is for, in the error).
///
/// # Errors
/// An existing `dir` without the mark, or an I/O failure.
pub fn make_owned(dir: &Path, what: &str, clear: bool) -> Result<()> {
    if std::fs::symlink_metadata(dir).is_ok() {
        if !dir.join(OWNED_MARK).is_file() {
            return Err(OutputError::NotOurs { dir: dir.to_path_buf(), what: what.to_string() });
        }
        if !clear {
            return Ok(());
        }
        std::fs::remove_dir_all(dir).map_err(io(format!("removing the old {}", dir.display())))?;
    }
    std::fs::create_dir_all(dir).map_err(io(format!("creating {}", dir.display())))?;
    std::fs::write(dir.join(OWNED_MARK), format!("{what}\n"))
        .map_err(io(format!("writing {}", dir.join(OWNED_MARK).display())))
}

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
    _lock: lock::OutLock,
}

impl RunDir {
    /// Prepares `out` for a command reading `inputs`; call it only after every input
    /// has been read and checked. `progress` names the file whose presence means the
    /// run has something to keep (e.g. `episodes.jsonl`, `state.json`).
    ///
    /// # Errors
    /// An `out` that overlaps an input or is a dangling link, another process writing
    /// it, an existing folder without `resume` or `force`, an `OUT.replaced` left by an
    /// interrupted `--force` run, or a failure to rename or create a folder.
    pub fn prepare(
        out: &Path,
        inputs: &Inputs,
        resume: bool,
        force: bool,
        progress: &'static str,
    ) -> Result<Self> {
        let lock = inputs.claim(out, ".replaced")?;
        let aside = sibling(out, ".replaced");
        let mut dir = Self {
            out: out.to_path_buf(),
            aside: None,
            created: false,
            progress,
            settled: false,
            _lock: lock,
        };
        if resume {
            // A resumed `--force` run completes the replacement when it finishes.
            dir.aside = aside.exists().then_some(aside);
        } else if out.exists() {
            if !force {
                return Err(OutputError::RunExists { out: out.to_path_buf() });
            }
            if aside.exists() {
                return Err(OutputError::ReplacedLeft { aside, out: out.to_path_buf() });
            }
            std::fs::rename(out, &aside).map_err(io(format!(
                "moving {} aside to {}",
                out.display(),
                aside.display()
            )))?;
            dir.aside = Some(aside);
        }
        if !dir.out.exists() {
            std::fs::create_dir_all(out).map_err(io(format!("creating {}", out.display())))?;
            // Only a folder this run made is removed again by a failure (never the
            // path it could not create, which may be the user's link or file).
            dir.created = true;
        }
        Ok(dir)
    }

    /// [`RunDir::prepare`] for a run that appends its rows to `episodes.jsonl` beside
    /// the `config.json` they were run with (`rank`, `plan`): rows without that
    /// config cannot be checked against the settings, so resuming them is refused.
    ///
    /// # Errors
    /// As [`RunDir::prepare`], and rows without a `config.json` on `--resume`.
    pub fn prepare_episodes(out: &Path, inputs: &Inputs, resume: bool, force: bool) -> Result<Self> {
        if resume && out.join("episodes.jsonl").exists() && !out.join("config.json").is_file() {
            return Err(OutputError::RowsWithoutConfig { out: out.to_path_buf() });
        }
        Self::prepare(out, inputs, resume, force, "episodes.jsonl")
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
                .map_err(io(format!("removing the replaced run {}", aside.display()))),
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
            let cleared = if std::fs::symlink_metadata(&self.out).is_ok() {
                std::fs::remove_dir_all(&self.out)
            } else {
                Ok(())
            };
            let restored = cleared.and_then(|()| std::fs::rename(aside, &self.out));
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

/// A staging directory for an output folder.
pub struct Staged {
    target: PathBuf,
    tmp: PathBuf,
    _lock: lock::OutLock,
}

impl Staged {
    /// Prepares `target` for a command reading `inputs` (refusing an existing one
    /// unless `force`); call it only after every input has been read and checked.
    ///
    /// # Errors
    /// A `target` that overlaps an input or is a dangling link, another process
    /// writing it, an existing one without `force`, an `OUT.partial` that is not the
    /// tool's, or an I/O failure.
    pub fn new(target: &Path, force: bool, inputs: &Inputs) -> Result<Self> {
        let lock = inputs.claim(target, ".partial")?;
        if std::fs::symlink_metadata(target).is_ok() && !force {
            return Err(OutputError::Exists { out: target.to_path_buf() });
        }
        let tmp = sibling(target, ".partial");
        make_owned(&tmp, "a command's output while it is written", true)?;
        Ok(Self { target: target.to_path_buf(), tmp, _lock: lock })
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
        let _ = std::fs::remove_file(self.tmp.join(OWNED_MARK));
        match std::fs::symlink_metadata(&self.target) {
            Ok(m) if m.is_dir() => std::fs::remove_dir_all(&self.target),
            Ok(_) => std::fs::remove_file(&self.target),
            Err(_) => Ok(()),
        }
        .map_err(io(format!("removing old {}", self.target.display())))?;
        std::fs::rename(&self.tmp, &self.target)
            .map_err(io(format!("moving {} into place", self.target.display())))?;
        Ok(self.target.clone())
    }

    /// Moves each entry of the staging directory into the existing target folder,
    /// refusing (before moving anything) names the target already holds.
    pub fn commit_into(self) -> Result<PathBuf> {
        let _ = std::fs::remove_file(self.tmp.join(OWNED_MARK));
        let reading = || io(format!("reading {}", self.tmp.display()));
        let entries: Vec<PathBuf> = std::fs::read_dir(&self.tmp)
            .map_err(reading())?
            .map(|e| e.map(|e| e.path()))
            .collect::<std::io::Result<_>>()
            .map_err(reading())?;
        let taken: Vec<String> = entries
            .iter()
            .filter_map(|e| e.file_name())
            .filter(|n| self.target.join(n).exists())
            .map(|n| n.to_string_lossy().into_owned())
            .collect();
        if !taken.is_empty() {
            std::fs::remove_dir_all(&self.tmp).map_err(io(format!("removing {}", self.tmp.display())))?;
            return Err(OutputError::Holds { target: self.target.clone(), taken });
        }
        for e in &entries {
            let dst = self.target.join(e.file_name().unwrap_or_default());
            std::fs::rename(e, &dst).map_err(io(format!("moving {} to {}", e.display(), dst.display())))?;
        }
        std::fs::remove_dir(&self.tmp).map_err(io(format!("removing {}", self.tmp.display())))?;
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
