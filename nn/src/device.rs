//! Which burn device runs the models: Flex on the CPU by default, or a GPU.
//!
//! burn 0.22 has one `Device` type for every backend, so the models need nothing
//! but the device value. The CPU build (the default, what CI runs) has Flex
//! only. A binary built with `--features cuda` also has burn's CUDA backend,
//! chosen at run time with `EVALHARNESS_DEVICE=cuda` (or `cuda:N` for GPU N);
//! one built with `--features wgpu` has burn's wgpu backend (WGSL shaders; on Linux
//! it runs on Vulkan), chosen with `EVALHARNESS_DEVICE=wgpu` (the adapter wgpu
//! prefers) or `wgpu:N` (discrete GPU N). Asking for a backend the binary was not
//! built with is an error that says how to build it, never a silent fall-back to
//! the CPU.
//!
//! Why two GPU features: burn's CUDA backend does not build on a machine without
//! internet access to GitHub (its `cubecl-llvm` build script downloads LLVM), so a
//! GPU binary made on such a machine is a wgpu one; Vulkan drivers come with
//! NVIDIA's, and Mesa's lavapipe runs the same binary on a CPU for a check (its
//! `wm eval` equals Flex's: BENCHMARKS.md, "a wgpu GPU build", 2026-11-25). burn's
//! `vulkan` feature (SPIR-V shaders instead of WGSL) was tried first and crashed
//! inside lavapipe (Mesa 22.3 and 25.0) while autotuning its matmul kernels.

use burn::tensor::Device;

/// The environment variable that picks the device.
pub const ENV: &str = "EVALHARNESS_DEVICE";

/// A device request that this binary cannot serve.
#[derive(Debug, thiserror::Error)]
#[error("{ENV}={value}: {message}")]
pub struct DeviceError {
    /// The requested value.
    pub value: String,
    /// Why it cannot be used.
    pub message: String,
}

/// The device named by `EVALHARNESS_DEVICE` (Flex when unset or empty).
///
/// # Errors
/// [`DeviceError`] for an unknown name or a backend not compiled in.
pub fn selected() -> Result<Device, DeviceError> {
    parse(&std::env::var(ENV).unwrap_or_default())
}

/// Parses a device name: `""`, `cpu` or `flex` → Flex; `cuda` or `cuda:N` → CUDA GPU N;
/// `wgpu` → the adapter wgpu prefers, `wgpu:N` → discrete GPU N.
///
/// # Errors
/// [`DeviceError`] for an unknown name or a backend not compiled in.
pub fn parse(value: &str) -> Result<Device, DeviceError> {
    let err = |message: String| DeviceError { value: value.to_string(), message };
    let v = value.trim().to_ascii_lowercase();
    match v.as_str() {
        "" | "cpu" | "flex" => return Ok(Device::flex()),
        _ => {}
    }
    let unknown = || err("unknown device (use cpu, cuda, cuda:N, wgpu or wgpu:N)".into());
    // A GPU name is its cargo feature's name, with an optional `:N`.
    let Some((backend, rest)) =
        [Gpu::Cuda, Gpu::Wgpu].into_iter().find_map(|g| v.strip_prefix(g.feature()).map(|rest| (g, rest)))
    else {
        return Err(unknown());
    };
    let index = match rest.strip_prefix(':') {
        None if rest.is_empty() => None,
        Some(n) => Some(n.parse::<usize>().map_err(|_| err(format!("'{n}' is not a GPU index")))?),
        None => return Err(unknown()),
    };
    let device = match backend {
        Gpu::Cuda => cuda(index.unwrap_or(0)),
        Gpu::Wgpu => wgpu(index),
    };
    device.ok_or_else(|| {
        let feature = backend.feature();
        err(format!(
            "this binary has no {feature} backend: build it with `cargo build --release --features {feature}`"
        ))
    })
}

/// The GPU backends a binary may be built with.
#[derive(Clone, Copy)]
enum Gpu {
    Cuda,
    Wgpu,
}

impl Gpu {
    /// The cargo feature that compiles the backend in, also its name in `EVALHARNESS_DEVICE`.
    fn feature(self) -> &'static str {
        match self {
            Gpu::Cuda => "cuda",
            Gpu::Wgpu => "wgpu",
        }
    }
}

#[cfg(feature = "cuda")]
fn cuda(index: usize) -> Option<Device> {
    Some(Device::cuda(index))
}

#[cfg(not(feature = "cuda"))]
fn cuda(_index: usize) -> Option<Device> {
    None
}

/// `None` → the adapter wgpu's heuristics prefer (the only one on lavapipe);
/// `Some(n)` → discrete GPU `n`.
#[cfg(feature = "wgpu")]
fn wgpu(index: Option<usize>) -> Option<Device> {
    use burn::tensor::DeviceKind;
    let kind = index.map_or(DeviceKind::DefaultDevice, DeviceKind::DiscreteGpu);
    Some(Device::wgpu(kind))
}

#[cfg(not(feature = "wgpu"))]
fn wgpu(_index: Option<usize>) -> Option<Device> {
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_bad_ones_are_named() {
        for ok in ["", "cpu", "FLEX", " flex "] {
            assert_eq!(parse(ok).map(|d| d == Device::flex()).ok(), Some(true), "{ok:?}");
        }
        let bad = parse("tpu").unwrap_err().to_string();
        assert!(bad.starts_with("EVALHARNESS_DEVICE=tpu: unknown device"), "{bad}");
        assert!(parse("cuda:x").unwrap_err().to_string().contains("'x' is not a GPU index"));
        assert!(parse("cudax").is_err());
        assert!(parse("wgpu:").is_err());
        assert!(parse("wgpux").unwrap_err().to_string().contains("unknown device"));
        if cfg!(not(feature = "cuda")) {
            let msg = parse("cuda:1").unwrap_err().to_string();
            assert!(msg.contains("no cuda backend") && msg.contains("--features cuda"), "{msg}");
        }
        if cfg!(not(feature = "wgpu")) {
            let msg = parse("WGPU:0").unwrap_err().to_string();
            assert!(msg.contains("no wgpu backend") && msg.contains("--features wgpu"), "{msg}");
        }
    }
}
