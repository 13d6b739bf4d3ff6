//! The machine-learning infrastructure the world model, the policies and the judges share,
//! so that none of them depends on another for it:
//!
//! - [`device`]: which burn device runs the models (Flex, or a GPU by `EVALHARNESS_DEVICE`);
//! - [`frames`]: byte frames to tensors and back;
//! - [`weights`]: burn weights copied into the [`kernels`]' plain arrays;
//! - [`optim`]: the weight EMA, global-norm clipping and the warm-up schedule;
//! - [`layers`]: layer constructors;
//! - [`import`]: reading other code's checkpoints (`.pth`, `.safetensors`) by key, checked.

pub mod device;
pub mod frames;
pub mod import;
pub mod layers;
pub mod optim;
pub mod weights;

pub use import::ImportError;
pub use weights::UnsupportedLayer;
