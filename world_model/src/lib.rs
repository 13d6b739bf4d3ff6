//! DriftWorld in burn: an action-conditioned video world model trained with the
//! drifting loss (Lu, Chen, Ye, Du 2026), so that it predicts a chunk of future
//! frames in one forward pass.
//!
//! - [`drift`]: the drifting loss; [`drift_step`]: a batch's drifting loss (fields,
//!   self-forcing); [`motion`]: its motion weighting; [`unet`]: the action-conditioned U-Net;
//! - [`autoencoder`] + [`train_ae`]: the frame autoencoder and its trainer; [`codec`]:
//!   autoencoder latents or pixels, the space the U-Net works in;
//! - CPU inference kernels: [`cpu_decoder`] + [`direct_conv`] + [`winograd`] (with
//!   [`winograd::upsample`] for its upsampling layers), the decoder;
//!   [`cpu_kernels`] + [`winograd_batch`], the U-Net ([`unet::cpu`]): whole-batch GEMM,
//!   GroupNorm, im2col and Winograd convolutions; [`elementwise`]: `exp` and statistics;
//! - [`latents`], [`train_wm`], [`optim`]: latent windows and the U-Net trainer
//!   (drifting, MSE and diffusion objectives); [`context_noise`]: corrupted training histories;
//! - [`model`]: a trained world model for inference; [`rollout`]: autoregressive
//!   generation, chunk by chunk; [`eval`]: video-quality metrics;
//! - [`data`]: datasets with a held-out split.

pub mod autoencoder;
pub mod codec;
pub mod context_noise;
pub mod cpu_decoder;
pub mod cpu_kernels;
pub mod data;
pub mod device;
pub mod direct_conv;
pub mod drift;
pub mod drift_step;
pub mod elementwise;
pub mod error;
pub mod eval;
pub mod latents;
pub mod model;
pub mod motion;
pub mod optim;
pub mod padded;
pub mod rollout;
pub mod train_ae;
pub mod train_wm;
pub mod unet;
pub mod winograd;
pub mod winograd_batch;

pub use error::WorldModelError;
