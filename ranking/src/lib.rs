//! `rank` as a library: from its clap arguments ([`args::RankArgs`]) to a finished run folder
//! and the exit code of its gates.
//!
//! One process ([`one::run_with`], reached through [`run::run`]): every input checked before
//! `--out` is touched, the task's defaults resolved (`checkpoints/<task>/rank.toml`), the
//! world model, judge and policies loaded once, the batches run by the engine on `--jobs` workers (rows streamed to
//! `episodes.jsonl` as batches finish; `--resume` continues from whole batches, `--shard i/n`
//! and `--claims` run part of them), then `results.json` written once, the episode tables,
//! the report and the stdout summary ([`summary`]). `--processes N` ([`processes`]) runs N
//! such shard processes at once, joins them with `runner::merge` and finishes the joined rows
//! as one run. The rules it relies on (run configurations, resume, merge, claims, media)
//! are [`runner`]'s; this crate is their order.
//!
//! What it needs of the binary: an [`runner::command::Invocation`] (the command line recorded
//! in `config.json`, whether bars show) and where result lines go ([`one::Caller`]); and that
//! the binary answers to `rank-shard FILE` ([`run::run_shard`]) and `render-worker`, which
//! it starts itself again as ([`processes::SHARD_COMMAND`], [`run::RENDER_WORKER_COMMAND`]).

pub mod args;
pub mod error;
pub mod one;
pub mod processes;
pub mod run;
mod summary;

pub use args::RankArgs;
pub use error::RankError;
pub use one::{Caller, prepare_run};
pub use run::{run, run_shard};
