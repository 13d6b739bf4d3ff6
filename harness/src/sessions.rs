//! The sessions of a training run, for its provenance: `sessions.jsonl` in the run folder
//! holds one line per session (command, commit, first and last step), typed as
//! [`Session`].
//!
//! A session that ends normally (its step budget, `--max-minutes`, Ctrl-C) appends its
//! own line. One that is killed (SIGKILL, a machine that goes away, a crash) cannot, yet
//! its checkpoints are kept and `--resume` continues from them; so a session writes
//! `session_open.json` when it starts, and the next session of the run turns a file it
//! finds there into that session's line, ending at the checkpoint the run resumes from
//! (the steps after it were lost with the process). Without this, a run's provenance
//! would list fewer steps than its weights have.
//!
//! Lines are written through `serde_json::Value` (keys in alphabetical order), as they
//! were when they were assembled with `json!`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// Where the session in progress is described until it ends.
pub const OPEN_SESSION: &str = "session_open.json";
/// One line per finished (or recovered) session.
pub const SESSIONS: &str = "sessions.jsonl";
/// The run's checkpoint state, whose step and training seconds a session ends at.
pub const STATE: &str = "state.json";

/// A sessions file that cannot be read or written.
#[derive(Debug, thiserror::Error)]
pub enum SessionError {
    /// A file could not be read, written or removed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The checkpoint's state file cannot be read or holds no step.
    #[error(transparent)]
    State(#[from] crate::runfile::RunFileError),
    /// A file does not parse.
    #[error("{}: {source}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's error.
        source: serde_json::Error,
    },
}

/// One session of a run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// Its command line.
    pub command: String,
    /// The commit of the binary that ran it.
    pub commit: String,
    /// The step it started from.
    pub from_step: u64,
    /// The step it ended at (none while it runs).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub to_step: Option<u64>,
    /// Training seconds of the run up to its end, over all sessions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub elapsed_s_total: Option<f64>,
    /// How it ended, when not normally.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ended: Option<String>,
    /// A note added by hand to a session recorded before sessions were recorded by the
    /// trainers (some shipped models' first sessions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

/// The part of a checkpoint's state file read here.
#[derive(Deserialize)]
struct Checkpoint {
    step: u64,
    #[serde(default)]
    elapsed_s: f64,
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> SessionError + '_ {
    move |source| SessionError::Io { path: path.to_path_buf(), source }
}

fn parse(path: &Path) -> impl FnOnce(serde_json::Error) -> SessionError + '_ {
    move |source| SessionError::Parse { path: path.to_path_buf(), source }
}

/// `step` and `elapsed_s` of the checkpoint in `out` (`state.json`); zeros without one.
///
/// # Errors
/// A state file that cannot be read or does not hold a step (never taken for none).
pub fn checkpoint_at(out: &Path) -> Result<(u64, f64), SessionError> {
    let path = out.join(STATE);
    if !path.is_file() {
        return Ok((0, 0.0));
    }
    let c: Checkpoint = crate::driver::read_state(&path)?;
    Ok((c.step, c.elapsed_s))
}

/// The step of the checkpoint in `out`, 0 without one.
///
/// # Errors
/// As [`checkpoint_at`].
pub fn read_step(out: &Path) -> Result<u64, SessionError> {
    Ok(checkpoint_at(out)?.0)
}

/// Marks the start of a session (`command`, run by a binary of `commit`) that will train
/// `out` from step `from`: first records a previous session that never ended (see the
/// module docs), then writes [`OPEN_SESSION`] for this one.
///
/// # Errors
/// A file of the run that cannot be read or written.
pub fn open_session(out: &Path, command: &str, commit: &str, from: u64) -> Result<(), SessionError> {
    std::fs::create_dir_all(out).map_err(io(out))?;
    recover_interrupted(out)?;
    let open = Session {
        command: command.into(),
        commit: commit.into(),
        from_step: from,
        to_step: None,
        elapsed_s_total: None,
        ended: None,
        note: None,
    };
    let path = out.join(OPEN_SESSION);
    let mut text = serde_json::to_string_pretty(&open).map_err(parse(&path))?;
    text.push('\n');
    std::fs::write(&path, text).map_err(io(&path))
}

/// Turns a left-over [`OPEN_SESSION`] into a `sessions.jsonl` line that ends at the run's
/// checkpoint.
fn recover_interrupted(out: &Path) -> Result<(), SessionError> {
    let path = out.join(OPEN_SESSION);
    if !path.is_file() {
        return Ok(());
    }
    let text = std::fs::read_to_string(&path).map_err(io(&path))?;
    let open: Session = serde_json::from_str(&text).map_err(parse(&path))?;
    let (step, elapsed_s) = checkpoint_at(out)?;
    tracing::warn!(
        from = open.from_step,
        to = step,
        "the run's previous session did not end normally; recorded up to its last checkpoint"
    );
    let ended = "interrupted (the process was killed): recorded by the run's next session, up to the \
                 checkpoint it resumed from; steps after that checkpoint were lost";
    append(
        out,
        &Session { to_step: Some(step), elapsed_s_total: Some(elapsed_s), ended: Some(ended.into()), ..open },
    )?;
    std::fs::remove_file(&path).map_err(io(&path))
}

/// Appends this session (`command` of a binary of `commit`, from step `from` to `to`,
/// `elapsed_s` of training over all sessions) to `out/sessions.jsonl`, closes
/// [`OPEN_SESSION`] and returns every session so far, so that a run trained over several
/// sessions keeps each command and commit.
///
/// # Errors
/// A file of the run that cannot be read or written, or a line that does not parse.
pub fn record_session(
    out: &Path,
    command: &str,
    commit: &str,
    (from, to): (u64, u64),
    elapsed_s: f64,
) -> Result<Vec<Session>, SessionError> {
    let line = Session {
        command: command.into(),
        commit: commit.into(),
        from_step: from,
        to_step: Some(to),
        elapsed_s_total: Some(elapsed_s),
        ended: None,
        note: None,
    };
    append(out, &line)?;
    let open = out.join(OPEN_SESSION);
    if open.is_file() {
        std::fs::remove_file(&open).map_err(io(&open))?;
    }
    let path = out.join(SESSIONS);
    let text = std::fs::read_to_string(&path).map_err(io(&path))?;
    text.lines().map(|l| serde_json::from_str(l).map_err(parse(&path))).collect()
}

/// Appends one line to `out/sessions.jsonl`.
fn append(out: &Path, line: &Session) -> Result<(), SessionError> {
    let path = out.join(SESSIONS);
    let value = serde_json::to_value(line).map_err(parse(&path))?;
    let mut f = std::fs::OpenOptions::new().create(true).append(true).open(&path).map_err(io(&path))?;
    crate::runfile::append_line(&mut f, &value).map_err(io(&path))
}

/// Why a `provenance.json` in `dir` that records `recorded` steps does not describe the
/// weights there, if it does not: its steps differ from the checkpoint's (a session was
/// killed after a checkpoint, so no session wrote provenance for the steps since). `None`
/// when they agree or when there is no checkpoint state to compare with.
///
/// # Errors
/// A state file that cannot be read.
pub fn stale_provenance(dir: &Path, recorded: Option<u64>) -> Result<Option<String>, SessionError> {
    if !dir.join(STATE).is_file() {
        return Ok(None);
    }
    let step = read_step(dir)?;
    Ok((recorded != Some(step)).then(|| {
        format!(
            "{}: provenance.json records {} steps but the checkpoint (state.json) is at step {step}: \
             a training session was interrupted after it saved a checkpoint",
            dir.display(),
            recorded.map_or("no".to_string(), |s| s.to_string()),
        )
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(out: &Path) -> Vec<Session> {
        let text = std::fs::read_to_string(out.join(SESSIONS)).unwrap_or_default();
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    }

    #[test]
    fn a_killed_session_is_recorded_up_to_its_checkpoint_by_the_next() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        // The first training process ends normally at step 100.
        open_session(&out, "train --steps 300", "c1", 0).unwrap();
        std::fs::write(out.join(STATE), r#"{"step":100,"elapsed_s":50.0}"#).unwrap();
        let all = record_session(&out, "train --steps 300", "c1", (0, 100), 50.0).unwrap();
        assert_eq!(all.len(), 1);
        assert!(!out.join(OPEN_SESSION).exists());
        // Lines keep their keys in alphabetical order.
        let first = std::fs::read_to_string(out.join(SESSIONS)).unwrap();
        assert_eq!(
            first,
            "{\"command\":\"train --steps 300\",\"commit\":\"c1\",\"elapsed_s_total\":50.0,\"from_step\":0,\"to_step\":100}\n"
        );
        // The second starts at 100, checkpoints at 150 and is killed (no record_session).
        open_session(&out, "train --resume", "c2", 100).unwrap();
        std::fs::write(out.join(STATE), r#"{"step":150,"elapsed_s":80.5}"#).unwrap();
        let stale = stale_provenance(&out, Some(100)).unwrap().expect("provenance is behind the checkpoint");
        assert!(stale.contains("records 100 steps") && stale.contains("at step 150"), "{stale}");
        // The third finds the second's open file and records it from 100 to 150.
        open_session(&out, "train --resume --max-minutes 0", "c3", 150).unwrap();
        let got = lines(&out);
        assert_eq!(got.len(), 2);
        assert_eq!((got[1].command.as_str(), got[1].commit.as_str()), ("train --resume", "c2"));
        assert_eq!((got[1].from_step, got[1].to_step), (100, Some(150)));
        assert_eq!(got[1].elapsed_s_total, Some(80.5));
        assert!(got[1].ended.as_deref().unwrap().starts_with("interrupted"));
        let all = record_session(&out, "train --resume --max-minutes 0", "c3", (150, 150), 80.5).unwrap();
        assert_eq!(all.len(), 3);
        assert!(all[2].ended.is_none());
        assert!(!out.join(OPEN_SESSION).exists());
        assert_eq!(stale_provenance(&out, Some(150)).unwrap(), None);
    }

    #[test]
    fn no_checkpoint_no_staleness_and_a_broken_state_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(stale_provenance(dir.path(), Some(3)).unwrap(), None);
        assert_eq!(read_step(dir.path()).unwrap(), 0);
        // Regression: an unreadable state.json was read as step 0.
        std::fs::write(dir.path().join(STATE), "{\"step\": \"x\"}").unwrap();
        let e = read_step(dir.path()).unwrap_err().to_string();
        assert!(e.contains("state.json"), "{e}");
    }
}
