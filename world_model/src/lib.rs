//! DriftWorld in burn: an action-conditioned video world model trained with the
//! drifting loss (Lu, Chen, Ye, Du 2026), so that it predicts a chunk of future
//! frames in one forward pass.
//!
//! Built so far: the drifting loss ([`drift`]).

pub mod drift;
