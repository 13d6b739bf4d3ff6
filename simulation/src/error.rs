//! What can stop `simulate`, `collect` or `dataset`: a flag or input refused before
//! anything is written, the libraries they drive (each error kept whole, with its source),
//! and the context a step adds ("policy NAME", "loading scenario S") around one of them.

use harness::task::TaskError;

/// A failed data command.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A flag, or the combination of flags and inputs, refused; the message names them.
    #[error("{0}")]
    Refused(String),
    /// What the command was doing when `source` failed.
    #[error("{what}")]
    In {
        /// The step, naming its flag, file, policy or seed.
        what: String,
        /// What failed.
        #[source]
        source: Box<SimError>,
    },
    /// A small JSON file that cannot be read or written.
    #[error(transparent)]
    Json(#[from] runner::command::JsonFileError),
    /// A value that cannot be written as JSON.
    #[error("encoding JSON: {0}")]
    Encode(#[source] serde_json::Error),
    /// A file or folder.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The output folder (or an input placed inside it).
    #[error(transparent)]
    Output(#[from] runner::output::OutputError),
    /// The run layer: a world model, judge or default input.
    #[error(transparent)]
    Run(#[from] runner::RunError),
    /// The device the environment names.
    #[error(transparent)]
    Device(#[from] nn::device::DeviceError),
    /// A seed range.
    #[error(transparent)]
    Seeds(#[from] harness::seed::SeedRangeError),
    /// A run's `episodes.jsonl`.
    #[error(transparent)]
    Rows(#[from] harness::rows::RowsError),
    /// A dataset's arrays or attributes.
    #[error(transparent)]
    Replay(#[from] harness::replay::ReplayError),
    /// A dataset's zarr metadata.
    #[error(transparent)]
    Zarr(#[from] harness::zarr::ZarrError),
    /// A task, its scenario file or its episodes.
    #[error(transparent)]
    Scenario(#[from] scenarios::ScenarioError),
    /// A task's episode or scripted run.
    #[error(transparent)]
    Task(#[from] TaskError),
    /// The paired engine.
    #[error(transparent)]
    Engine(#[from] engine::EngineError),
    /// A policy checkpoint.
    #[error(transparent)]
    Policy(#[from] policies::dir::PolicyLoadError),
    /// A world model.
    #[error(transparent)]
    WorldModel(#[from] world_model::WorldModelError),
    /// A judge.
    #[error(transparent)]
    Judge(#[from] judges::JudgeError),
    /// A GIF.
    #[error(transparent)]
    Gif(#[from] reports::gif::GifError),
}

impl SimError {
    /// A task's error as the command's: the command's own error when its episode sink
    /// returned one ([`SimError::into_task`]), else the task's.
    pub fn from_task(e: TaskError) -> Self {
        match e.0.downcast::<SimError>() {
            Ok(own) => *own,
            Err(other) => Self::Task(TaskError(other)),
        }
    }

    /// The command's error returned through a task's episode sink.
    pub fn into_task(self) -> TaskError {
        TaskError::new(self)
    }
}

/// A data command's result.
pub type Result<T, E = SimError> = std::result::Result<T, E>;

runner::context_for!(SimError);

pub(crate) use runner::refuse;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_sent_through_a_task_comes_back_as_itself() {
        let own = SimError::Refused("--mix: 'x' is not name=weight".into());
        let back = SimError::from_task(own.into_task());
        assert!(matches!(back, SimError::Refused(ref m) if m.contains("--mix")), "{back:?}");
        let io = std::io::Error::other("disk full");
        let e = Err::<(), _>(io).context("writing d.zarr").unwrap_err();
        assert_eq!(e.to_string(), "writing d.zarr");
        assert_eq!(std::error::Error::source(&e).map(ToString::to_string).as_deref(), Some("disk full"));
    }
}
