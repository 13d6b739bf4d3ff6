//! Errors of the scenario simulators, each naming the file, field, seed or step at fault.

use std::path::PathBuf;

/// What can go wrong while loading or running a scenario.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// A scenario name that no simulator implements.
    #[error("unknown scenario '{name}' (available: {available})")]
    UnknownScenario {
        /// The name asked for.
        name: String,
        /// The names that exist.
        available: String,
    },
    /// A scenario file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Malformed TOML or an unknown key.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message (with line and key).
        message: String,
    },
    /// A value out of its allowed range.
    #[error("{path}: field '{field}': {reason}")]
    InvalidField {
        /// The file.
        path: PathBuf,
        /// Dotted field path.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// MuJoCo refused the generated model.
    #[error("MuJoCo could not load the {scenario} model: {message}")]
    Model {
        /// Scenario name.
        scenario: String,
        /// MuJoCo's message.
        message: String,
    },
    /// The simulation state became NaN/inf or left the world (a diverging simulation).
    #[error("non-finite or diverging {scenario} state at seed {seed}, step {step}: {detail}")]
    NonFinite {
        /// Scenario name.
        scenario: String,
        /// Episode seed.
        seed: u64,
        /// Control step at which it was detected.
        step: u32,
        /// Which quantity.
        detail: String,
    },
    /// MuJoCo's offscreen renderer failed (no EGL/GL context, ...).
    #[error("MuJoCo renderer: {message} (run scripts/setup.sh for the EGL/Mesa packages)")]
    Render {
        /// What failed.
        message: String,
    },
    /// Rejection sampling of a reset found no admissible state.
    #[error(
        "seed {seed}: no initial state after {draws} draws; the scenario's '{field}' admits none (lower it)"
    )]
    ImpossibleReset {
        /// Episode seed.
        seed: u64,
        /// Draws made.
        draws: u32,
        /// The field that rules every draw out.
        field: String,
    },
    /// An action that is NaN or infinite.
    #[error("non-finite action {action:?} at seed {seed}, step {step}")]
    BadAction {
        /// Episode seed.
        seed: u64,
        /// Control step.
        step: u32,
        /// The action.
        action: Vec<f64>,
    },
    /// An action with the wrong number of entries for the task.
    #[error("action of {got} entries at seed {seed}: the task takes {expected}")]
    BadActionSize {
        /// Episode seed.
        seed: u64,
        /// Entries the task takes.
        expected: usize,
        /// Entries given.
        got: usize,
    },
    /// robosuite's scene assets are not where the build or
    /// `EVALHARNESS_ROBOSUITE_ASSETS` says.
    #[error(
        "robosuite assets missing: {dir} has no {missing}; run scripts/setup.sh (it unpacks the \
         pinned robosuite wheel's assets into .robosuite/assets) or set EVALHARNESS_ROBOSUITE_ASSETS"
    )]
    MissingAssets {
        /// The folder looked in.
        dir: PathBuf,
        /// The first file not found, relative to it.
        missing: String,
    },
    /// An element the scene composer expects in a robosuite asset file is absent.
    #[error("robosuite asset {file}: no {kind} named '{name}'")]
    MissingElement {
        /// The asset file.
        file: PathBuf,
        /// Body, geom, joint, site, ...
        kind: &'static str,
        /// The element's name.
        name: String,
    },
    /// A scenario that exists but cannot yet do what was asked.
    #[error("scenario '{scenario}' does not support {what} yet")]
    Unsupported {
        /// The scenario.
        scenario: String,
        /// What it cannot do.
        what: String,
    },
    /// A scripted behaviour's name the task does not have.
    #[error("unknown {what} '{name}' (built-in{listed})")]
    UnknownBehaviour {
        /// What was asked for ("policy", "lift behaviour", …).
        what: String,
        /// The name.
        name: String,
        /// The behaviours there are, as the message lists them.
        listed: String,
    },
    /// The worker threads could not be started.
    #[error("starting worker threads: {0}")]
    Threads(#[source] rayon::ThreadPoolBuildError),
    /// A recorded episode whose arrays do not fit the task's dataset layout.
    #[error("recorded episode seed {seed}: {message}")]
    Recorded {
        /// The episode's seed.
        seed: u64,
        /// What does not fit, naming the step.
        message: String,
    },
    /// One episode of a batch failed.
    #[error("{scenario}episode seed {seed} ({behaviour})")]
    Episode {
        /// The task's name and a space, or nothing (Push-T's episodes say only their seed).
        scenario: String,
        /// The episode's seed.
        seed: u64,
        /// Its behaviour.
        behaviour: String,
        /// What went wrong.
        #[source]
        source: Box<ScenarioError>,
    },
}

impl From<ScenarioError> for harness::task::TaskError {
    fn from(e: ScenarioError) -> Self {
        Self::new(e)
    }
}
