//! `evalharness train ...`: the four training commands (the frame autoencoder, the world
//! model, a diffusion policy, a judge of imagined frames) and `train adapt` (a model folder
//! moved to another rendering of its frames, `adapt.rs`), from their typed arguments ([`args`])
//! to a finished run or model folder.
//!
//! Each command checks its flags and inputs before the output folder is touched, prepares
//! the folder (`--resume` continues a run, `--force` replaces one only once the new run is
//! complete), refuses a `--resume` whose typed flags contradict the saved run, records the
//! session, hands the work to its library trainer (`world_model::train_ae`,
//! `world_model::train_wm`, `policies::train`, `judges::train`), and writes the run's
//! provenance. A run can be time-boxed with `--max-minutes` and continued with `--resume`.
//!
//! Why a crate of its own: the binary only parses the command line and dispatches here,
//! handing over what it knows of the process ([`Invocation`]); the commands' logic, their
//! errors ([`error::TrainError`]) and their tests live beside the trainers they drive.

mod adapt;
pub mod args;
mod autoencoder;
mod common;
pub mod error;
mod judge;
mod policy;
mod wm_inputs;
pub mod world_model;

pub use error::TrainError;

pub(crate) use runner::say;

pub use runner::command::Invocation;

/// Runs the training command `cmd`; each result line goes to `say`.
///
/// # Errors
/// A refused flag or input, or what the trainer and the run folder report.
pub fn run(cmd: &args::TrainCommand, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<(), TrainError> {
    match cmd {
        args::TrainCommand::Autoencoder(a) => autoencoder::autoencoder(a, inv, say),
        args::TrainCommand::WorldModel(a) => world_model::run(a, inv, say),
        args::TrainCommand::Policy(a) => policy::run(a, inv, say),
        args::TrainCommand::Judge(a) => judge::run(a, inv, say),
        args::TrainCommand::Adapt(a) => adapt::run(a, inv, say),
    }
}
