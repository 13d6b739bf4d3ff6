//! Judges of imagined frames: what scores a world model's frames where the task has no
//! hand-written judge of its own (Lift, Can), or where a researcher brings GPC's.
//!
//! - [`folder`]: a judge folder (`judge.json` and its weights) and [`folder::FrameJudge`],
//!   which implements [`harness::judge::Judge`]: a learned network ([`folder::JudgeNet`], the
//!   policies' frame encoder and a one-logit head), a hand-written [`rule`], or GPC's reward
//!   predictors imported by [`pose`];
//! - [`train`]: the learned judge's trainer, resumable ([`run`]: its `.train` folder); [`read`]: a recorded episode read as `rank` reads an
//!   imagined one; [`metrics`]: which frames `rank` judges and a judge's metrics, shared by the
//!   three so that none imports another in a circle;
//! - [`provenance`]: how a judge was made (trained, hand-written or imported) and the
//!   persistence rule chosen for it, typed;
//! - [`error`]: [`JudgeError`], naming the folder, file or dataset.

pub mod error;
pub mod folder;
pub mod metrics;
pub mod pose;
pub mod provenance;
pub mod read;
pub mod rule;
pub mod run;
pub mod train;

pub use error::JudgeError;
