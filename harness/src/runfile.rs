//! A training run's `config.json`: written when the run starts, read back when it
//! resumes.
//!
//! Every trainer (autoencoder, world model, policy) resumes the same way: the saved
//! configuration wins over the command line, so a resumed run is the run that was
//! started, except for its length, which `--steps`/`--epochs` may extend or
//! shorten (the caller's `adjust` applies it; the file is rewritten when it
//! changes anything).

use std::path::{Path, PathBuf};

use serde::Serialize;
use serde::de::DeserializeOwned;

/// A run file that could not be read, parsed or written.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct RunFileError {
    /// The file.
    pub path: PathBuf,
    /// What went wrong.
    pub message: String,
}

fn write<C: Serialize>(path: &Path, c: &C) -> Result<(), RunFileError> {
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let text = serde_json::to_string_pretty(c).map_err(|e| err(e.to_string()))?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    }
    std::fs::write(path, text).map_err(|e| err(e.to_string()))
}

/// The configuration of a run whose file is `path`: `fresh`, written to `path`, for
/// a new run; the saved one, after `adjust` (which returns whether it changed
/// anything), when resuming.
///
/// # Errors
/// [`RunFileError`] naming `path` when it cannot be written, or, when resuming, is
/// missing or does not parse as `C`.
pub fn resume_or_start<C: Serialize + DeserializeOwned>(
    path: &Path,
    fresh: C,
    resume: bool,
    adjust: impl FnOnce(&mut C) -> bool,
) -> Result<C, RunFileError> {
    if !resume {
        write(path, &fresh)?;
        return Ok(fresh);
    }
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    let mut saved: C = serde_json::from_str(&text).map_err(|e| err(e.to_string()))?;
    if adjust(&mut saved) {
        write(path, &saved)?;
    }
    Ok(saved)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Cfg {
        lr: f64,
        steps: u64,
    }

    #[test]
    fn a_resumed_run_keeps_its_config_but_may_change_its_length() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run/config.json");
        let started =
            resume_or_start(&path, Cfg { lr: 1e-3, steps: 100 }, false, |_| unreachable!()).unwrap();
        assert_eq!(started, Cfg { lr: 1e-3, steps: 100 });
        // The command line now says lr 5e-4 and 300 steps: only the length is taken.
        let resumed = resume_or_start(&path, Cfg { lr: 5e-4, steps: 300 }, true, |c| {
            c.steps = 300;
            true
        })
        .unwrap();
        assert_eq!(resumed, Cfg { lr: 1e-3, steps: 300 });
        let again = resume_or_start(&path, Cfg { lr: 0.0, steps: 0 }, true, |_| false).unwrap();
        assert_eq!(again, resumed, "the extension was saved");
    }

    #[test]
    fn resuming_without_a_config_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("config.json");
        let err = resume_or_start(&path, Cfg { lr: 1.0, steps: 1 }, true, |_| false).unwrap_err();
        assert_eq!(err.path, path);
        std::fs::write(&path, "{\"lr\": 1.0}").unwrap();
        let err = resume_or_start(&path, Cfg { lr: 1.0, steps: 1 }, true, |_| false).unwrap_err();
        assert!(err.message.contains("steps"), "{}", err.message);
    }
}
