//! What can stop an `import`: a flag or input refused before anything is written, the
//! importers and loaders it drives (each error kept whole, with its source), and the context
//! a step adds ("--checkpoint FILE", "checking the imported policy") around one of them.

/// A failed import.
#[derive(Debug, thiserror::Error)]
pub enum ImportCmdError {
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
        source: Box<ImportCmdError>,
    },
    /// A small JSON file that cannot be read or written.
    #[error(transparent)]
    Json(#[from] runner::command::JsonFileError),
    /// A value that cannot be written as JSON.
    #[error("encoding JSON: {0}")]
    Encode(#[from] serde_json::Error),
    /// A file or folder.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// A checkpoint's content fingerprint.
    #[error(transparent)]
    Fingerprint(#[from] harness::fingerprint::FingerprintError),
    /// The output folder (or an input placed inside it).
    #[error(transparent)]
    Output(#[from] runner::output::OutputError),
    /// The device the environment names.
    #[error(transparent)]
    Device(#[from] nn::device::DeviceError),
    /// Another program's checkpoint: a tensor missing, of another shape, or unreadable.
    #[error(transparent)]
    Checkpoint(#[from] nn::import::ImportError),
    /// The task a checkpoint runs on.
    #[error(transparent)]
    Scenario(#[from] scenarios::ScenarioError),
    /// A world model, imported or written.
    #[error(transparent)]
    WorldModel(#[from] world_model::WorldModelError),
    /// A policy checkpoint, imported or written.
    #[error(transparent)]
    Policy(#[from] policies::dir::PolicyLoadError),
    /// A judge, imported or written.
    #[error(transparent)]
    Judge(#[from] judges::JudgeError),
}

/// An import's result.
pub type Result<T, E = ImportCmdError> = std::result::Result<T, E>;

runner::context_for!(ImportCmdError);

pub(crate) use runner::refuse;
