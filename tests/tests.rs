//! Integration tests: drive the real `evalharness` binary on tiny inputs.

// A pipeline test runs one command after another through the binary, checking each on the
// way; the workspace's 100-line rule (`clippy::too_many_lines`) is for library and command code.
#![allow(clippy::too_many_lines)]

mod adapt;
mod agreement;
mod can_models;
mod dataset;
mod deploy;
mod docs;
mod guarantees;
mod import;
mod judge;
mod lift;
mod lift_models;
mod pipeline;
mod plan;
mod reach;
mod reliability;
mod render_workers;
mod shipped;
mod simulate;
mod train;
mod train_wm;
mod util;
