//! A trainer's checkpoint as one unit: the weights, the EMA weights, the optimiser and
//! the state file must all come from the same step, or `--resume` would carry on from a
//! mixture without noticing.
//!
//! Writing several files cannot be one rename, so a checkpoint is staged and then
//! committed by a manifest, as a database commits a transaction:
//! 1. every file is written into `RUN/UNIT.next/` ([`begin`], [`Stage::path`]);
//! 2. `UNIT.next/UNIT.json` (each file's name and SHA-256) is written atomically:
//!    from here on the checkpoint exists;
//! 3. the files are renamed over the run's own, the manifest last (`RUN/UNIT.json`),
//!    and the staging folder is removed.
//!
//! `UNIT` names the checkpoint ([`MAIN`] for a trainer's own; a policy run also keeps
//! its encoder pre-training's as [`ENCODER`]), so two units share a folder.
//!
//! [`recover`], called before a resume loads anything, rolls a committed stage
//! forward (a kill during step 3), drops an uncommitted one (a kill or a full disk
//! during step 1 or 2: the previous checkpoint is untouched), and then checks every
//! file against the manifest, naming the one that differs. A run written before
//! checkpoints had a manifest resumes as it did then, with a warning.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::runfile::{RunFileError, write_atomic};

/// A trainer's own checkpoint.
pub const MAIN: &str = "checkpoint";
/// A policy run's encoder pre-training checkpoint.
pub const ENCODER: &str = "encoder_checkpoint";

/// The staging folder of `unit` inside a run folder.
fn stage_dir(run: &Path, unit: &str) -> PathBuf {
    run.join(format!("{unit}.next"))
}

/// The manifest's file name of `unit`.
fn manifest_name(unit: &str) -> String {
    format!("{unit}.json")
}

/// One file of a checkpoint, as the manifest records it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Entry {
    /// The file's name inside the run folder.
    pub name: String,
    /// `sha256:<hex>` of its bytes.
    pub sha256: String,
}

/// The manifest: the files that make up the checkpoint.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// Every file, in the order they were staged.
    pub files: Vec<Entry>,
}

fn fail(path: &Path, message: impl std::fmt::Display) -> RunFileError {
    RunFileError { path: path.to_path_buf(), message: message.to_string() }
}

/// A checkpoint being written; see the module docs.
#[derive(Debug)]
pub struct Stage {
    run: PathBuf,
    unit: &'static str,
    next: PathBuf,
    names: Vec<String>,
}

/// Starts checkpoint `unit` of the run in `run`: an empty `UNIT.next/` (one left by
/// an interrupted write is removed; it was never committed, or [`recover`] would
/// have moved it).
///
/// # Errors
/// [`RunFileError`] naming the staging folder when it cannot be made.
pub fn begin(run: &Path, unit: &'static str) -> Result<Stage, RunFileError> {
    let next = stage_dir(run, unit);
    if next.exists() {
        std::fs::remove_dir_all(&next).map_err(|e| fail(&next, e))?;
    }
    std::fs::create_dir_all(&next).map_err(|e| fail(&next, e))?;
    Ok(Stage { run: run.to_path_buf(), unit, next, names: Vec::new() })
}

impl Stage {
    /// Where to write the checkpoint's file `name` (it is moved to `RUN/name` on commit).
    pub fn path(&mut self, name: &str) -> PathBuf {
        if !self.names.iter().any(|n| n == name) {
            self.names.push(name.to_string());
        }
        self.next.join(name)
    }

    /// Commits the staged files (see the module docs).
    ///
    /// # Errors
    /// [`RunFileError`] naming a staged file that is missing or cannot be read, or a
    /// rename that failed. Before the manifest is written the previous checkpoint is
    /// untouched; after it, [`recover`] completes the commit.
    pub fn commit(self) -> Result<(), RunFileError> {
        let mut files = Vec::with_capacity(self.names.len());
        for name in &self.names {
            let path = self.next.join(name);
            let sha256 = crate::fingerprint::file(&path).map_err(|e| fail(&path, e.source))?;
            files.push(Entry { name: name.clone(), sha256 });
        }
        let manifest = self.next.join(manifest_name(self.unit));
        let text = serde_json::to_string_pretty(&Manifest { files }).map_err(|e| fail(&manifest, e))?;
        write_atomic(&manifest, &text)?;
        roll_forward(&self.run, self.unit)
    }
}

/// Moves a committed stage's files into the run folder, the manifest last.
fn roll_forward(run: &Path, unit: &str) -> Result<(), RunFileError> {
    let next = stage_dir(run, unit);
    let name = manifest_name(unit);
    let manifest: Manifest = read_manifest(&next.join(&name))?;
    for e in &manifest.files {
        let (from, to) = (next.join(&e.name), run.join(&e.name));
        // A kill during an earlier roll-forward may have moved this file already.
        if from.exists() {
            std::fs::rename(&from, &to).map_err(|err| fail(&to, err))?;
        }
    }
    let to = run.join(&name);
    std::fs::rename(next.join(&name), &to).map_err(|e| fail(&to, e))?;
    std::fs::remove_dir_all(&next).map_err(|e| fail(&next, e))
}

fn read_manifest(path: &Path) -> Result<Manifest, RunFileError> {
    let text = std::fs::read_to_string(path).map_err(|e| fail(path, e))?;
    serde_json::from_str(&text).map_err(|e| fail(path, format!("not a checkpoint manifest: {e}")))
}

/// Whether an interrupted write left a staged checkpoint of `unit` in `run` (committed
/// or not): [`recover`] has something to do even where the unit's own files are absent.
pub fn pending(run: &Path, unit: &str) -> bool {
    stage_dir(run, unit).exists()
}

/// Makes the run folder's checkpoint whole before a resume reads it, and checks it
/// (see the module docs).
///
/// # Errors
/// [`RunFileError`] naming a file whose content is not the one its manifest
/// records (written by something else, or damaged), or one that is missing.
pub fn recover(run: &Path, unit: &str) -> Result<(), RunFileError> {
    let next = stage_dir(run, unit);
    let name = manifest_name(unit);
    if next.join(&name).is_file() {
        tracing::warn!("{}: completing a checkpoint an interrupted run had committed", run.display());
        roll_forward(run, unit)?;
    } else if next.exists() {
        tracing::warn!(
            "{}: dropping a checkpoint an interrupted run had not finished writing; resuming from the one before",
            next.display()
        );
        std::fs::remove_dir_all(&next).map_err(|e| fail(&next, e))?;
    }
    let path = run.join(&name);
    if !path.is_file() {
        tracing::warn!(
            "{}: no checkpoint manifest (a run written before checkpoints had one); its files are not cross-checked",
            run.display()
        );
        return Ok(());
    }
    for e in read_manifest(&path)?.files {
        let file = run.join(&e.name);
        let now = crate::fingerprint::file(&file).map_err(|err| fail(&file, err.source))?;
        if now != e.sha256 {
            return Err(fail(
                &file,
                format!(
                    "is not the file of the last checkpoint ({} records {}, the file is {now}); \
                     restore it, or start the run again with --force",
                    path.display(),
                    e.sha256
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn save(run: &Path, step: &str) -> Stage {
        let mut st = begin(run, MAIN).unwrap();
        for name in ["model.bpk", "ema.bpk", "state.json"] {
            std::fs::write(st.path(name), format!("{name} at {step}")).unwrap();
        }
        st
    }

    fn read(run: &Path, name: &str) -> String {
        std::fs::read_to_string(run.join(name)).unwrap()
    }

    #[test]
    fn a_checkpoint_is_all_old_or_all_new_after_any_kill() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        save(run, "1").commit().unwrap();
        recover(run, MAIN).unwrap();
        assert_eq!(read(run, "model.bpk"), "model.bpk at 1");
        // Killed while staging (no manifest yet): step 1 stays, whole.
        let st = save(run, "2");
        drop(st);
        recover(run, MAIN).unwrap();
        assert!(!stage_dir(run, MAIN).exists());
        assert_eq!(
            (read(run, "model.bpk"), read(run, "state.json")),
            ("model.bpk at 1".into(), "state.json at 1".into())
        );
        // Killed after the commit point, with one file moved: rolled forward to step 3.
        let mut st = save(run, "3");
        let next = st.path("model.bpk").parent().unwrap().to_path_buf();
        let files: Vec<Entry> = ["model.bpk", "ema.bpk", "state.json"]
            .iter()
            .map(|n| Entry { name: n.to_string(), sha256: crate::fingerprint::file(&next.join(n)).unwrap() })
            .collect();
        write_atomic(&next.join(manifest_name(MAIN)), &serde_json::to_string(&Manifest { files }).unwrap())
            .unwrap();
        std::fs::rename(next.join("model.bpk"), run.join("model.bpk")).unwrap();
        recover(run, MAIN).unwrap();
        for n in ["model.bpk", "ema.bpk", "state.json"] {
            assert_eq!(read(run, n), format!("{n} at 3"));
        }
    }

    #[test]
    fn a_file_from_another_step_is_refused_by_name() {
        // At 92f9f2b the files were renamed one at a time with nothing tying them
        // together: a model.bpk of another step resumed silently.
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        save(run, "1").commit().unwrap();
        std::fs::write(run.join("ema.bpk"), "ema.bpk at 2").unwrap();
        let e = recover(run, MAIN).unwrap_err().to_string();
        assert!(e.contains("ema.bpk") && e.contains("last checkpoint"), "{e}");
        std::fs::remove_file(run.join("ema.bpk")).unwrap();
        assert!(recover(run, MAIN).unwrap_err().to_string().contains("ema.bpk"));
    }
}
