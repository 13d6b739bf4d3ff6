//! Integration tests: drive the real `evalharness` binary on tiny inputs.

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
