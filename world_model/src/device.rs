//! Which burn device runs the models: Flex on the CPU by default, or a GPU.
//!
//! burn 0.22 has one `Device` type for every backend, so the models need nothing
//! but the device value. The CPU build (the default, what CI runs) has Flex
//! only. A binary built with `--features cuda` also has burn's CUDA backend,
//! chosen at run time with `EVALHARNESS_DEVICE=cuda` (or `cuda:N` for GPU N);
//! asking for a backend the binary was not built with is an error that says how
//! to build it, never a silent fall-back to the CPU.

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

/// Parses a device name: `""`, `cpu` or `flex` → Flex; `cuda` or `cuda:N` → CUDA GPU N.
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
    let Some(rest) = v.strip_prefix("cuda") else {
        return Err(err("unknown device (use cpu, cuda or cuda:N)".into()));
    };
    let index = match rest.strip_prefix(':') {
        None if rest.is_empty() => 0,
        Some(n) => n.parse::<usize>().map_err(|_| err(format!("'{n}' is not a GPU index")))?,
        None => return Err(err("unknown device (use cpu, cuda or cuda:N)".into())),
    };
    cuda(index).ok_or_else(|| {
        err("this binary has no GPU backend: build it with `cargo build --release --features cuda`".into())
    })
}

#[cfg(feature = "cuda")]
fn cuda(index: usize) -> Option<Device> {
    Some(Device::cuda(index))
}

#[cfg(not(feature = "cuda"))]
fn cuda(_index: usize) -> Option<Device> {
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
        if cfg!(not(feature = "cuda")) {
            let msg = parse("cuda:1").unwrap_err().to_string();
            assert!(msg.contains("--features cuda"), "{msg}");
        }
    }
}
