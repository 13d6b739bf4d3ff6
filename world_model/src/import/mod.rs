//! World models trained elsewhere, brought into evalharness's own format once, so that
//! `rank`, `plan`, `wm eval` and `simulate --replay-imagined` never parse a foreign file.
//!
//! - [`driftworld`]: the official DriftWorld code's `torch.save` checkpoints (its U-Net is
//!   evalharness's [`crate::unet::UNet`] with per-frame attention norms and head-major qkv rows).
//! - the readers every importer shares are [`nn::import`]'s.
//!
//! An import refuses a missing, unexpected or mis-shaped key, a tensor that is not float32 and
//! a non-finite value, naming the key; nothing is written then (the binary stages the output).

pub mod driftworld;

#[cfg(test)]
mod tests;
