//! DriftWorld in burn: an action-conditioned video world model trained with the
//! drifting loss (Lu, Chen, Ye, Du 2026), so that it predicts a chunk of future
//! frames in one forward pass.
//!
//! Built so far: the drifting loss ([`drift`]), the frame autoencoder
//! ([`autoencoder`]) with its resumable trainer ([`train_ae`]), and dataset
//! loading with a held-out split ([`data`]).

pub mod autoencoder;
pub mod data;
pub mod drift;
pub mod error;
pub mod train_ae;
pub mod unet;

pub use error::WorldModelError;
