//! The run layer: output folders that never look complete before they are
//! ([`output`]: staged outputs, resumable run folders, inputs checked before outputs,
//! one writer per output), and for `rank` and `plan` what a run folder's `config.json` holds, as
//! typed structs ([`config::RankConfig`], [`config::PlanConfig`]), and the rules that
//! read it back: which settings `--resume` may change and how a run grows
//! ([`resume`]), and which shard folders `merge` may join ([`shards`]) and how
//! ([`merge`]); and the
//! list of filmstrips a run's report shows ([`filmstrips`]), and the ranges a
//! `results.json` must keep to be reported ([`check`]); and the batches the shard
//! processes of one run share out as they go ([`claims`]); and the report's filmstrips,
//! from the frames a run keeps or replays ([`media`]), and its report ([`report`]); and
//! the batches one process of a run runs, appended as they finish ([`batches`]), and the
//! models a run reads, loaded, checked and fingerprinted ([`inputs`]), and whether they learned on
//! frames of the scene the run renders ([`frames_seen`]); and what a bare
//! `rank --scenario NAME` runs, from the task's shipped folder and `rank.toml` ([`defaults`]);
//! and what the command crates share around their errors and output ([`command`]);
//! and `agreement`'s metrics of any predictor's scores from a CSV ([`agreement`]);
//! and what every command shares around a run: the ranges of the counts its flags take
//! ([`bounds`]) and its progress bars on stderr ([`progress`]).
//!
//! Why a crate of its own: the configuration is the contract between the processes of
//! one run (the shards of `rank --processes`, `merge`, `report`, a later `--resume`),
//! and it names types of three crates (the world model's configuration, the judge's
//! label and metrics), so it sits above them and below the binary.

pub mod agreement;
pub mod batches;
pub mod bounds;
pub mod check;
pub mod claims;
pub mod command;
pub mod config;
pub mod defaults;
pub mod error;
pub mod filmstrips;
pub mod frames_seen;
pub mod inputs;
pub mod media;
pub mod merge;
pub mod output;
pub mod progress;
pub mod report;
pub mod resume;
pub mod shards;

pub use config::{JudgeSettings, PlanConfig, RankConfig, RunSettings, Span};
pub use error::RunError;

#[cfg(test)]
mod fuzz;
