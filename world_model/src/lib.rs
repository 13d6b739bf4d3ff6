//! DriftWorld in burn: an action-conditioned video world model trained with the
//! drifting loss (Lu, Chen, Ye, Du 2026), so that it predicts a chunk of future
//! frames in one forward pass.
//!
//! - [`drift`]: the drifting loss; [`drift_step`]: a batch's drifting loss (fields,
//!   self-forcing); [`motion`]: its motion weighting; [`unet`]: the action-conditioned U-Net;
//! - [`autoencoder`] + [`train_ae`]: the frame autoencoder and its trainer; [`codec`]:
//!   autoencoder latents or pixels, the space the U-Net works in;
//! - CPU inference on the [`kernels`] crate: [`cpu_decoder`], the decoder, and
//!   [`unet::cpu`], the U-Net (burn's weights copied by [`nn::weights`]);
//! - [`latents`], [`train_wm`]: latent windows and the U-Net trainer (its loop's parts in
//!   `train_wm_parts`: windows, warm start, checkpoints, one step's loss)
//!   (drifting, MSE and diffusion objectives); [`context_noise`]: corrupted training histories;
//! - [`model`]: a trained world model for inference; [`rollout`]: autoregressive
//!   generation, chunk by chunk; [`eval`]: video-quality metrics;
//! - [`data`]: datasets with a held-out split; [`action`]: how actions are normalised;
//! - [`import`]: world models trained by other code (the official DriftWorld checkpoints).

pub mod action;
pub mod autoencoder;
pub mod codec;
pub mod context_noise;
pub mod cpu_decoder;
pub mod data;
pub mod drift;
pub mod drift_step;
pub mod error;
pub mod eval;
pub mod import;
pub mod latents;
pub mod model;
pub mod motion;
pub mod rollout;
pub mod train_ae;
pub mod train_wm;
mod train_wm_config;
mod train_wm_parts;
pub mod unet;

pub use error::{SettingError, WorldModelError};
#[cfg(all(test, feature = "wgpu"))]
mod gpu_tests;
