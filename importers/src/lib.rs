//! `evalharness import ...`: models trained by other code (the official DriftWorld world
//! model, GPC's reward predictors, GPC's, LeRobot's and robomimic's diffusion policies)
//! converted once into evalharness's own folders, checked by loading them back, with their
//! provenance.
//!
//! The formats themselves (key tables, shapes, statistics) are read by the libraries'
//! importers (`world_model::import`, `policies::import_*`, `judges::pose`); this crate is
//! the commands around them: flags, output folders, the round-trip check and the record.
//!
//! Why a crate of its own: the binary only parses the command line and dispatches here,
//! handing over what it knows of the process ([`Invocation`]).

pub mod args;
pub mod error;
mod judge;
mod policy;
mod robomimic;
mod world_model;

pub use error::ImportCmdError;

pub(crate) use runner::say;

pub use runner::command::Invocation;

/// Runs the import `cmd`; each result line goes to `say`.
///
/// # Errors
/// A refused flag or input, an unreadable checkpoint, or what the output folder reports.
pub fn run(
    cmd: &args::ImportCommand,
    inv: &Invocation,
    say: &mut dyn FnMut(&str),
) -> Result<(), ImportCmdError> {
    match cmd {
        args::ImportCommand::WorldModel(a) => world_model::run(a, inv, say),
        args::ImportCommand::Judge(a) => judge::run(a, inv, say),
        args::ImportCommand::Policy(a) => policy::run(a, inv, say),
    }
}
