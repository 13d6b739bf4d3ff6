//! The sessions of a training run, for its provenance: `sessions.jsonl` in the
//! run folder holds one line per session (command, commit, first and last step).
//!
//! A session that ends normally (its step budget, `--max-minutes`, Ctrl-C) appends
//! its own line. One that is killed (SIGKILL, a machine that goes away, a crash)
//! cannot, yet its checkpoints are kept and `--resume` continues from them; so a
//! session writes `session_open.json` when it starts, and the next session of the
//! run turns a file it finds there into that session's line, ending at the
//! checkpoint the run resumes from (the steps after it were lost with the process).
//! Without this, a run's provenance would list fewer steps than its weights have.

use std::path::Path;

use anyhow::{Context, Result};
use serde_json::json;

use super::git_commit;
use crate::output::{read_json, write_json};

/// Where the session in progress is described until it ends.
const OPEN_SESSION: &str = "session_open.json";

/// `step` and `elapsed_s` of the checkpoint in `out` (`state.json`), zeros if none.
fn read_checkpoint(out: &Path) -> (u64, f64) {
    let state = std::fs::read_to_string(out.join("state.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
        .unwrap_or_default();
    (state["step"].as_u64().unwrap_or(0), state["elapsed_s"].as_f64().unwrap_or(0.0))
}

/// The step of the checkpoint in `out`, 0 if none.
pub(super) fn read_step(out: &Path) -> u64 {
    read_checkpoint(out).0
}

/// Marks the start of a session that will train `out` from step `from`: first
/// records a previous session that never ended (see the module docs), then
/// writes [`OPEN_SESSION`] for this one.
pub(super) fn open_session(out: &Path, command: &str, from: u64) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    recover_interrupted(out)?;
    write_json(
        &out.join(OPEN_SESSION),
        &json!({"command": command, "commit": git_commit(), "from_step": from}),
    )
}

/// Turns a left-over [`OPEN_SESSION`] into a `sessions.jsonl` line that ends at the
/// run's checkpoint.
fn recover_interrupted(out: &Path) -> Result<()> {
    let path = out.join(OPEN_SESSION);
    if !path.is_file() {
        return Ok(());
    }
    let mut line = read_json(&path)?;
    let (step, elapsed_s) = read_checkpoint(out);
    line["to_step"] = json!(step);
    line["elapsed_s_total"] = json!(elapsed_s);
    line["ended"] = json!(
        "interrupted (the process was killed): recorded by the run's next session, up to the \
         checkpoint it resumed from; steps after that checkpoint were lost"
    );
    tracing::warn!(
        from = line["from_step"].as_u64().unwrap_or(0),
        to = step,
        "the run's previous session did not end normally; recorded up to its last checkpoint"
    );
    append(out, &line)?;
    std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))
}

/// Appends this session (from step `from` to `to`, `elapsed_s` of training over
/// all sessions) to `out/sessions.jsonl`, closes [`OPEN_SESSION`] and returns
/// every session so far, so that a run trained over several sessions keeps each
/// command and commit.
pub(super) fn record_session(
    out: &Path,
    command: &str,
    from: u64,
    to: u64,
    elapsed_s: f64,
) -> Result<Vec<serde_json::Value>> {
    let line = json!({"command": command, "commit": git_commit(), "from_step": from, "to_step": to, "elapsed_s_total": elapsed_s});
    append(out, &line)?;
    let open = out.join(OPEN_SESSION);
    if open.is_file() {
        std::fs::remove_file(&open).with_context(|| format!("removing {}", open.display()))?;
    }
    let path = out.join("sessions.jsonl");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    text.lines()
        .map(|l| serde_json::from_str(l).with_context(|| format!("{}: invalid line", path.display())))
        .collect()
}

/// Appends one JSON line to `out/sessions.jsonl`.
fn append(out: &Path, line: &serde_json::Value) -> Result<()> {
    let path = out.join("sessions.jsonl");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .with_context(|| format!("opening {}", path.display()))?;
    harness::runfile::append_line(&mut f, line).with_context(|| format!("writing {}", path.display()))
}

/// Why `provenance.json` in `dir` does not describe the weights there, if it does
/// not: its `steps` differ from the checkpoint's (a session was killed after a
/// checkpoint, so no session wrote provenance for the steps since). `None` when
/// they agree or when there is no checkpoint state to compare with.
pub(super) fn stale_provenance(dir: &Path, provenance: &serde_json::Value) -> Option<String> {
    if !dir.join("state.json").is_file() {
        return None;
    }
    let step = read_step(dir);
    let recorded = provenance["steps"].as_u64();
    (recorded != Some(step)).then(|| {
        format!(
            "{}: provenance.json records {} steps but the checkpoint (state.json) is at step {step}: \
             a training session was interrupted after it saved a checkpoint",
            dir.display(),
            recorded.map_or("no".to_string(), |s| s.to_string()),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lines(out: &Path) -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(out.join("sessions.jsonl")).unwrap_or_default();
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    }

    #[test]
    fn a_killed_session_is_recorded_up_to_its_checkpoint_by_the_next() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("run");
        // The first training process ends normally at step 100.
        open_session(&out, "train --steps 300", 0).unwrap();
        std::fs::write(out.join("state.json"), r#"{"step":100,"elapsed_s":50.0}"#).unwrap();
        let all = record_session(&out, "train --steps 300", 0, 100, 50.0).unwrap();
        assert_eq!(all.len(), 1);
        assert!(!out.join(OPEN_SESSION).exists());
        // The second starts at 100, checkpoints at 150 and is killed (no record_session).
        open_session(&out, "train --resume", 100).unwrap();
        std::fs::write(out.join("state.json"), r#"{"step":150,"elapsed_s":80.5}"#).unwrap();
        let prov = json!({"steps": 100});
        let stale = stale_provenance(&out, &prov).expect("provenance is behind the checkpoint");
        assert!(stale.contains("records 100 steps") && stale.contains("at step 150"), "{stale}");
        // The third finds the second's open file and records it from 100 to 150.
        open_session(&out, "train --resume --max-minutes 0", 150).unwrap();
        let got = lines(&out);
        assert_eq!(got.len(), 2);
        assert_eq!(got[1]["command"], "train --resume");
        assert_eq!((got[1]["from_step"].as_u64(), got[1]["to_step"].as_u64()), (Some(100), Some(150)));
        assert_eq!(got[1]["elapsed_s_total"].as_f64(), Some(80.5));
        assert!(got[1]["ended"].as_str().unwrap().starts_with("interrupted"));
        let all = record_session(&out, "train --resume --max-minutes 0", 150, 150, 80.5).unwrap();
        assert_eq!(all.len(), 3);
        assert!(all[2].get("ended").is_none());
        assert!(!out.join(OPEN_SESSION).exists());
        assert_eq!(stale_provenance(&out, &json!({"steps": 150})), None);
    }

    #[test]
    fn no_checkpoint_no_staleness() {
        let dir = tempfile::tempdir().unwrap();
        assert_eq!(stale_provenance(dir.path(), &json!({"steps": 3})), None);
        assert_eq!(read_step(dir.path()), 0);
    }
}
