//! Output folders: the run layer's [`runner::output`] (staging, resumable run folders,
//! inputs checked before outputs, one writer per output), re-exported for the
//! commands, and the JSON writer of their small files ([`runner::command::write_json`]).

pub use runner::command::write_json;
pub use runner::output::lock;
pub use runner::output::{Inputs, Staged};
