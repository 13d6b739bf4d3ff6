//! The loop skeleton every resumable trainer shares (autoencoder, world model,
//! policy encoder pre-training, policy, judge): when to stop, how long the run has
//! trained over all its sessions, its JSON-lines log, and its small state file.
//!
//! A trainer keeps its model, optimiser and step counter, and asks the [`Driver`]
//! the rest, so that every trainer stops, logs and checkpoints the same way. The loop itself
//! is [`Driver::train`]: a trainer says what one step is, when a checkpoint is due and how it
//! is saved ([`Steps`]), and the loop owns the order of things:
//! - it stops before a step once the session's deadline (`--max-minutes`,
//!   [`Clock`]) has passed or Ctrl-C was pressed ([`crate::stop`]), saving a
//!   checkpoint that `--resume` continues from;
//! - `elapsed_s` counts the training seconds of earlier sessions (from the
//!   checkpoint's state) plus this one's;
//! - the log resumes at the checkpoint ([`crate::runfile::open_log`] drops the
//!   lines a killed session wrote after it);
//! - the state file (`state.json` and the like) is written atomically
//!   ([`crate::runfile::write_atomic`]), so a killed run leaves the old state or
//!   the new one.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::runfile::{RunFileError, open_log, write_atomic};

/// A session's start and its deadline.
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    started: Instant,
    deadline: Option<Instant>,
}

impl Clock {
    /// A clock started now, out of time after `max_minutes` (never if `None`;
    /// at once if not positive).
    pub fn start(max_minutes: Option<f64>) -> Self {
        let started = Instant::now();
        let deadline = max_minutes.map(|m| started + Duration::from_secs_f64(m.max(0.0) * 60.0));
        Self { started, deadline }
    }

    /// The deadline, if any.
    pub fn deadline(&self) -> Option<Instant> {
        self.deadline
    }

    /// Whether the deadline has passed.
    pub fn out_of_time(&self) -> bool {
        self.deadline.is_some_and(|d| Instant::now() >= d)
    }

    /// Seconds since the clock started.
    pub fn seconds(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }
}

/// One session of a training loop: its clock, the seconds trained before it,
/// and its log.
pub struct Driver {
    clock: Clock,
    /// Another clock's deadline this session also stops at ([`Driver::stopping_at`]).
    deadline: Option<Instant>,
    before_s: f64,
    log: std::fs::File,
    log_path: PathBuf,
}

impl Driver {
    /// Starts a session that resumes at `step` of a run that had trained
    /// `elapsed_s` seconds (0 and 0 for a fresh run), logging to `log` whose
    /// lines count steps in `key` (lines after `step` are dropped).
    ///
    /// # Errors
    /// [`RunFileError`] naming the log when it cannot be read, rewritten or opened.
    pub fn start(
        log: &Path,
        key: &str,
        step: u64,
        elapsed_s: f64,
        clock: Clock,
    ) -> Result<Self, RunFileError> {
        Ok(Self {
            clock,
            deadline: None,
            before_s: elapsed_s,
            log: open_log(log, key, step)?,
            log_path: log.to_path_buf(),
        })
    }

    /// Stops also at `deadline`: a stage of a longer session (a policy's encoder
    /// pre-training) counts its own seconds but ends with the session's clock.
    #[must_use]
    pub fn stopping_at(mut self, deadline: Option<Instant>) -> Self {
        self.deadline = deadline;
        self
    }

    /// Whether to stop before the next step: the deadline has passed or a stop
    /// (Ctrl-C, SIGTERM) was requested.
    pub fn should_stop(&self) -> bool {
        self.clock.out_of_time()
            || self.deadline.is_some_and(|d| Instant::now() >= d)
            || crate::stop::requested()
    }

    /// Training seconds of the run: earlier sessions' plus this one's so far.
    pub fn elapsed_s(&self) -> f64 {
        self.before_s + self.clock.seconds()
    }

    /// Appends one line to the log.
    ///
    /// # Errors
    /// [`RunFileError`] naming the log when it cannot be written.
    pub fn log<T: Serialize + ?Sized>(&mut self, line: &T) -> Result<(), RunFileError> {
        crate::runfile::append_line(&mut self.log, line)
            .map_err(|e| RunFileError { path: self.log_path.clone(), message: e.to_string() })
    }
}

/// A trainer's part of the loop every trainer shares ([`Driver::train`]): one optimiser step
/// on its network, when a checkpoint is due, and how one is saved. `Net` is what an optimiser
/// step takes and gives back (burn's optimisers consume the module), with its optimiser.
pub trait Steps {
    /// The network and optimiser, moved through each step.
    type Net;
    /// One step's line in the log.
    type Line: Serialize;
    /// The trainer's error; a log line that cannot be written becomes one.
    type Error: From<RunFileError>;
    /// Steps done so far (the run's state).
    fn done(&self) -> u64;
    /// The step the run ends at.
    fn total(&self) -> u64;
    /// Takes the next optimiser step on `net`, with `elapsed_s` giving the run's training
    /// seconds when asked (after the step, for the state it records). Returns the network and
    /// the step's log line (`None`: this step writes none).
    ///
    /// # Errors
    /// The trainer's: a non-finite loss, a failed evaluation.
    fn step(&mut self, net: Self::Net, elapsed_s: &dyn Fn() -> f64) -> Stepped<Self>;
    /// Whether a checkpoint is due after the step just taken.
    fn checkpoint_due(&self) -> bool;
    /// Saves `net` and the run's state as its checkpoint, `elapsed_s` the training seconds now.
    ///
    /// # Errors
    /// A file that cannot be written.
    fn save(&mut self, net: &Self::Net, elapsed_s: f64) -> Result<(), Self::Error>;
    /// After each step's line and checkpoint: progress bars and the like.
    fn progress(&mut self) {}
    /// The session stops before step [`Steps::done`] (out of time, or Ctrl-C).
    fn stopping(&mut self) {}
}

/// What [`Steps::step`] gives back: the network and the step's log line, or the trainer's error.
pub type Stepped<S> = Result<(<S as Steps>::Net, Option<<S as Steps>::Line>), <S as Steps>::Error>;

impl Driver {
    /// Runs `steps` from its state until its last step or until the session stops
    /// ([`Driver::should_stop`], checked before every step): each step, then its log line,
    /// then a checkpoint when one is due, then progress; a checkpoint at the end either way,
    /// so `--resume` continues where this session stopped. Returns the network and whether the
    /// run reached its last step.
    ///
    /// # Errors
    /// What a step or a save returns, or a log line that cannot be written.
    pub fn train<S: Steps>(&mut self, steps: &mut S, mut net: S::Net) -> Result<(S::Net, bool), S::Error> {
        while steps.done() < steps.total() {
            if self.should_stop() {
                steps.stopping();
                break;
            }
            let (next, line) = steps.step(net, &|| self.elapsed_s())?;
            net = next;
            if let Some(line) = line {
                self.log(&line)?;
            }
            if steps.checkpoint_due() {
                steps.save(&net, self.elapsed_s())?;
            }
            steps.progress();
        }
        steps.save(&net, self.elapsed_s())?;
        let finished = steps.done() >= steps.total();
        Ok((net, finished))
    }
}

/// The progress a checkpoint saves in its state file (`state.json`), for a trainer that
/// saves nothing else there (the autoencoder's, the world model's and the judge's).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct State {
    /// Steps done.
    pub step: u64,
    /// Training seconds over all sessions.
    pub elapsed_s: f64,
}

/// Reads a run's state file.
///
/// # Errors
/// [`RunFileError`] naming `path` when it cannot be read or does not parse as `S`.
pub fn read_state<S: DeserializeOwned>(path: &Path) -> Result<S, RunFileError> {
    crate::runfile::read(path)
}

/// Writes a run's state file atomically.
///
/// # Errors
/// [`RunFileError`] naming `path` when it cannot be written.
pub fn write_state<S: Serialize>(path: &Path, state: &S) -> Result<(), RunFileError> {
    let text = serde_json::to_string(state)
        .map_err(|e| RunFileError { path: path.to_path_buf(), message: e.to_string() })?;
    write_atomic(path, &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clock_without_time_is_out_of_it_and_one_without_a_limit_never_is() {
        assert!(Clock::start(Some(0.0)).out_of_time());
        assert!(Clock::start(Some(-1.0)).out_of_time(), "a negative limit is no time at all");
        assert!(!Clock::start(Some(60.0)).out_of_time());
        let free = Clock::start(None);
        assert!(!free.out_of_time() && free.deadline().is_none());
    }

    #[test]
    fn a_resumed_session_counts_the_earlier_seconds_and_logs_after_the_checkpoint() {
        let dir = tempfile::tempdir().unwrap();
        let log = dir.path().join("log.jsonl");
        std::fs::write(&log, "{\"step\":1}\n{\"step\":2}\n{\"step\":3}\n").unwrap();
        // Checkpointed at step 2 after 10 s of training; the line of step 3 is dropped.
        let mut d = Driver::start(&log, "step", 2, 10.0, Clock::start(None)).unwrap();
        assert!(d.elapsed_s() >= 10.0 && d.elapsed_s() < 70.0, "{}", d.elapsed_s());
        assert!(!d.should_stop());
        d.log(&serde_json::json!({"step": 3, "loss": 0.5})).unwrap();
        let text = std::fs::read_to_string(&log).unwrap();
        assert_eq!(text, "{\"step\":1}\n{\"step\":2}\n{\"loss\":0.5,\"step\":3}\n");
        let out_of_time = Driver::start(&log, "step", 3, 0.0, Clock::start(Some(0.0))).unwrap();
        assert!(out_of_time.should_stop());
    }

    #[test]
    fn state_files_round_trip_and_name_the_file_on_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("state.json");
        write_state(&path, &State { step: 4, elapsed_s: 1.5 }).unwrap();
        assert_eq!(read_state::<State>(&path).unwrap(), State { step: 4, elapsed_s: 1.5 });
        std::fs::write(&path, "{\"step\":4}").unwrap();
        let e = read_state::<State>(&path).unwrap_err();
        assert!(e.path == path && e.message.contains("elapsed_s"), "{e}");
        let missing = dir.path().join("none.json");
        assert_eq!(read_state::<State>(&missing).unwrap_err().path, missing);
    }
}
