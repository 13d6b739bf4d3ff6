//! CPU inference kernels in plain Rust, shared by the world model's decoder and
//! U-Net and the policies' encoder and U-Net (`world_model::cpu_decoder`,
//! `world_model::unet::cpu`, `policies::cpu_encoder`, `policies::cpu_unet`).
//!
//! burn-flex runs each layer as separate passes over small tensors; these kernels
//! fuse them, and use Winograd's algorithm where it needs fewer multiply-adds.
//! Everything here works on `f32` slices: no burn types, so the crates that copy
//! burn's weights into these kernels (`nn::weights`) do the copying and
//! this crate only computes.
//!
//! - [`elementwise`]: the vectorisable `exp`, GroupNorm statistics, the AVX2 + FMA and AVX-512F checks;
//! - [`padded`]: bordered feature maps, GroupNorm + SiLU into the border;
//! - [`direct_conv`]: the direct 3x3 convolution (and the switch to Winograd);
//! - [`winograd`] (with [`winograd::upsample`]): Winograd F(2x2, 3x3) on one bordered map,
//!   and fused with nearest 2x upsampling;
//! - [`winograd_batch`]: Winograd over whole batches of channel-major images;
//! - [`matrix`]: matrix products, dense layers, GroupNorm with FiLM, im2col convolutions;
//! - [`avx512_gemm`]: the world model's matrix products on AVX-512 (`avx512_gemm::fast_matmul`, falling back to `matrix`);
//! - [`chain_gemm`]: matrix products with the same bits on every CPU (one FMA chain per element;
//!   AVX-512, AVX2 or scalar), for the imported policies' U-Nets;
//! - [`attention`]: multi-head self-attention over each image's positions.
//!
//! This crate is the project's one place for `unsafe` code: AVX2 + FMA and AVX-512 intrinsics,
//! and calls of functions compiled for those features after a run-time check. Each
//! block says why it is sound in a `SAFETY:` comment. (The one other block, in
//! `scenarios`, installs MuJoCo's log hook through its C API.)

pub mod attention;
pub mod avx512_gemm;
pub mod chain_gemm;
pub mod direct_conv;
pub mod elementwise;
pub mod matrix;
pub mod padded;
pub mod winograd;
pub mod winograd_batch;
