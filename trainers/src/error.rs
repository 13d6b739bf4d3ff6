//! What can stop a training command: a flag or input refused before anything is written,
//! the libraries it drives (each error kept whole, with its source), and the context a
//! step adds ("--init-from DIR", "reading FILE") around one of them.

/// A failed training command.
#[derive(Debug, thiserror::Error)]
pub enum TrainError {
    /// A flag, or the combination of flags and inputs, refused; the message names them.
    #[error("{0}")]
    Refused(String),
    /// What the command was doing when `source` failed.
    #[error("{what}")]
    In {
        /// The step, naming its flag or file.
        what: String,
        /// What failed.
        #[source]
        source: Box<TrainError>,
    },
    /// A small JSON file that cannot be read or written.
    #[error(transparent)]
    Json(#[from] runner::command::JsonFileError),
    /// An input or output folder, or a file in it.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// The output folder (or an input placed inside it).
    #[error(transparent)]
    Output(#[from] runner::output::OutputError),
    /// The device the environment names.
    #[error(transparent)]
    Device(#[from] nn::device::DeviceError),
    /// A run's configuration or state file.
    #[error(transparent)]
    RunFile(#[from] harness::runfile::RunFileError),
    /// A run's sessions.
    #[error(transparent)]
    Sessions(#[from] harness::sessions::SessionError),
    /// A dataset's arrays or attributes.
    #[error(transparent)]
    Replay(#[from] harness::replay::ReplayError),
    /// A dataset's zarr metadata.
    #[error(transparent)]
    Zarr(#[from] harness::zarr::ZarrError),
    /// The task a dataset names.
    #[error(transparent)]
    Scenario(#[from] scenarios::ScenarioError),
    /// Goal-free frames that cannot be made from a dataset.
    #[error(transparent)]
    GoalFree(#[from] scenarios::pusht::goal_free::GoalFreeError),
    /// The autoencoder or world-model trainer, or a model folder it reads.
    #[error(transparent)]
    WorldModel(#[from] world_model::WorldModelError),
    /// The policy trainer, or a policy checkpoint it reads.
    #[error(transparent)]
    Policy(#[from] policies::dir::PolicyLoadError),
    /// A policy's demonstrations.
    #[error(transparent)]
    Demos(#[from] policies::data::DataError),
    /// The judge trainer, or a judge folder it writes.
    #[error(transparent)]
    Judge(#[from] judges::JudgeError),
    /// The autoencoder's filmstrip of reconstructions.
    #[error(transparent)]
    Png(#[from] reports::png::PngError),
}

/// A training command's result.
pub type Result<T, E = TrainError> = std::result::Result<T, E>;

runner::context_for!(TrainError);

pub(crate) use runner::refuse;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn context_keeps_the_error_as_its_source() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = Err::<(), _>(io).context("reading x.json").unwrap_err();
        assert_eq!(e.to_string(), "reading x.json");
        let source = std::error::Error::source(&e).map(ToString::to_string);
        assert_eq!(source.as_deref(), Some("no such file"));
        let none = None::<u8>.context("--data d: no data/coverage array").unwrap_err();
        assert_eq!(none.to_string(), "--data d: no data/coverage array");
    }
}
