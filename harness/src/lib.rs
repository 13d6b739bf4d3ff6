//! evalharness core: what every other crate shares, with no burn or MuJoCo in sight.
//!
//! - [`seed`]: deterministic seed derivation (episode RNGs never depend on thread order);
//! - [`metrics`]: agreement metrics between predicted and true policy scores, with CIs;
//! - [`zarr`] and [`replay`]: the diffusion_policy / GPC replay-buffer dataset layout.

pub mod blosc;
pub mod metrics;
pub mod replay;
pub mod seed;
pub mod zarr;
