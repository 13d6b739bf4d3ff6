//! A training run's `config.json`: written when the run starts, read back when it
//! resumes.
//!
//! Every trainer (autoencoder, world model, policy) resumes the same way: the saved
//! configuration wins over the command line, so a resumed run is the run that was
//! started, except for its length, which `--steps`/`--epochs` may extend or
//! shorten (the caller's `adjust` applies it; the file is rewritten when it
//! changes anything).
//!
//! Its log resumes with it: [`open_log`] drops the lines a killed run wrote after
//! its last checkpoint, which the resumed run logs again.

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

/// Writes a run file (`config.json`) as pretty-printed JSON.
///
/// # Errors
/// [`RunFileError`] naming `path` when it cannot be written.
pub fn write_config<C: Serialize>(path: &Path, c: &C) -> Result<(), RunFileError> {
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let text = serde_json::to_string_pretty(c).map_err(|e| err(e.to_string()))?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| err(e.to_string()))?;
    }
    std::fs::write(path, text).map_err(|e| err(e.to_string()))
}

/// A run file read as `C`.
///
/// # Errors
/// [`RunFileError`] naming `path` when it is missing or does not parse as `C`.
pub fn read<C: DeserializeOwned>(path: &Path) -> Result<C, RunFileError> {
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let text = std::fs::read_to_string(path).map_err(|e| err(e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| err(e.to_string()))
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
        write_config(path, &fresh)?;
        return Ok(fresh);
    }
    let mut saved: C = read(path)?;
    if adjust(&mut saved) {
        write_config(path, &saved)?;
    }
    Ok(saved)
}

/// Writes `text` to `path` through a temporary file beside it and a rename, so a
/// process killed while writing leaves the old file or the new one, never a torn
/// one. For the small state files (`state.json`) saved with every checkpoint; the
/// weight files (burnpack) are written the same way by burn.
///
/// # Errors
/// [`RunFileError`] naming `path` when the temporary file cannot be written or
/// renamed.
pub fn write_atomic(path: &Path, text: &str) -> Result<(), RunFileError> {
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let tmp = path.with_file_name(name);
    std::fs::write(&tmp, text).map_err(|e| err(e.to_string()))?;
    std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))
}

/// Opens a run's JSON-lines log (one object with a step counter `key` per line,
/// e.g. `"step"`) for appending, first dropping the lines whose `key` is after
/// `step`, the checkpoint the run resumes from. A run killed between checkpoints
/// logged steps that the resumed run repeats; keeping both would give the log two
/// histories for the same steps. Lines without `key` (another stage's, sharing the
/// file) are kept. A last line without its newline was torn by a kill in the
/// middle of writing it and is dropped too, so the next line does not run on from
/// it. The file is rewritten (through a temporary file and a rename) only when a
/// line is dropped.
///
/// # Errors
/// [`RunFileError`] naming `path` when it cannot be read, rewritten or opened.
pub fn open_log(path: &Path, key: &str, step: u64) -> Result<std::fs::File, RunFileError> {
    let err = |m: String| RunFileError { path: path.to_path_buf(), message: m };
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => String::new(),
        Err(e) => return Err(err(e.to_string())),
    };
    let later = |line: &str| {
        serde_json::from_str::<serde_json::Value>(line)
            .ok()
            .and_then(|v| v[key].as_u64())
            .is_some_and(|s| s > step)
    };
    let whole = text.rfind('\n').map_or("", |i| &text[..=i]);
    let kept: Vec<&str> = whole.lines().filter(|l| !later(l)).collect();
    if whole.len() < text.len() || kept.len() < whole.lines().count() {
        let tmp = path.with_extension("jsonl.partial");
        std::fs::write(&tmp, kept.iter().flat_map(|l| [*l, "\n"]).collect::<String>())
            .map_err(|e| err(e.to_string()))?;
        std::fs::rename(&tmp, path).map_err(|e| err(e.to_string()))?;
    }
    std::fs::OpenOptions::new().create(true).append(true).open(path).map_err(|e| err(e.to_string()))
}

/// Appends `line` and its newline to `w` in one `write_all`. Formatting a
/// `serde_json::Value` straight into an unbuffered file (`writeln!(file, "{line}")`)
/// writes it token by token, so a run killed there left half a line that no
/// resume could read; one write leaves a whole line or, at worst, a torn last
/// line that [`open_log`] drops.
///
/// # Errors
/// The writer's error.
pub fn append_line<W: std::io::Write, T: Serialize + ?Sized>(w: &mut W, line: &T) -> std::io::Result<()> {
    let mut text = serde_json::to_string(line).map_err(std::io::Error::other)?;
    text.push('\n');
    w.write_all(text.as_bytes())
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
    fn write_atomic_replaces_the_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        std::fs::write(&path, "old").unwrap();
        write_atomic(&path, r#"{"step":2}"#).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), r#"{"step":2}"#);
        let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names, vec![std::ffi::OsString::from("state.json")]);
        let missing = dir.path().join("no_such_dir").join("state.json");
        let e = write_atomic(&missing, "x").unwrap_err();
        assert_eq!(e.path, missing);
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

    #[test]
    fn a_resumed_log_drops_the_steps_after_its_checkpoint() {
        use std::io::Write;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("train_log.jsonl");
        // A fresh run: no file yet.
        writeln!(open_log(&path, "step", 0).unwrap(), "{{\"step\":1}}").unwrap();
        // The run went on to step 4, was checkpointed at step 2 and killed.
        let mut log = open_log(&path, "step", 1).unwrap();
        for s in 2..=4 {
            writeln!(log, "{{\"step\":{s},\"loss\":0.5}}").unwrap();
        }
        writeln!(log, "not json").unwrap();
        writeln!(log, "{{\"encoder_step\":9}}").unwrap(); // another stage's counter
        drop(log);
        writeln!(open_log(&path, "step", 2).unwrap(), "{{\"step\":3,\"loss\":0.4}}").unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let kept = "{\"step\":1}\n{\"step\":2,\"loss\":0.5}\nnot json\n{\"encoder_step\":9}\n";
        assert_eq!(text, format!("{kept}{{\"step\":3,\"loss\":0.4}}\n"));
        // That stage resumes from its own counter, keeping the other lines.
        drop(open_log(&path, "encoder_step", 5).unwrap());
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, "{\"step\":1}\n{\"step\":2,\"loss\":0.5}\nnot json\n{\"step\":3,\"loss\":0.4}\n");
        assert!(!dir.path().join("train_log.jsonl.partial").exists());
        // A kill in the middle of a line tore it: it is dropped, and the next line
        // starts on a line of its own.
        std::fs::write(&path, "{\"step\":1}\n{\"step\":2,\"lo").unwrap();
        append_line(&mut open_log(&path, "step", 1).unwrap(), &serde_json::json!({"step": 2})).unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "{\"step\":1}\n{\"step\":2}\n");
        std::fs::write(&path, "{\"st").unwrap();
        drop(open_log(&path, "step", 0).unwrap());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "");
        let bad = dir.path().join("missing/dir/log.jsonl");
        assert_eq!(open_log(&bad, "step", 0).unwrap_err().path, bad);
    }

    /// Counts the writes it is given.
    #[derive(Default)]
    struct Writes(Vec<Vec<u8>>);

    impl std::io::Write for Writes {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.push(buf.to_vec());
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn a_log_line_is_written_whole_in_one_write() {
        use std::io::Write;
        let line = serde_json::json!({"step": 3, "loss": 0.5});
        // The cause of a torn line: formatting the value into the writer writes
        // it in pieces, any of which a kill can be the last.
        let mut pieces = Writes::default();
        writeln!(pieces, "{line}").unwrap();
        assert!(pieces.0.len() > 2, "{:?}", pieces.0.len());
        let mut whole = Writes::default();
        append_line(&mut whole, &line).unwrap();
        assert_eq!(whole.0, vec![b"{\"loss\":0.5,\"step\":3}\n".to_vec()]);
    }
}
