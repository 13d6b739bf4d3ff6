//! GPC-RANK planning (DriftWorld spec §11) on any task whose episodes have a
//! planning cost ([`harness::task::PlanCost`]) and copy themselves
//! ([`harness::task::Env::fork`]): a policy proposes several action chunks per
//! decision and a planner (none, the world model, or the simulator) picks the one
//! to execute. The `plan` command drives batches of seeds through [`run_batch`].
//!
//! - [`state`]: the shared context, each episode's live state and the rows;
//! - [`episodes`]: the lockstep loop over a batch, the picking and spreading rules;
//! - `imagine`: a decision's proposals imagined in the world model or the simulator;
//! - [`results`]: the run's statistics per planner, its `results.json`.

pub mod episodes;
mod imagine;
pub mod results;
pub mod state;

pub use episodes::{pick, pick_with_margin, run_batch, spread};
pub use state::{PlanCtx, PlanOut, PlanRow, Planner, plan_key};
