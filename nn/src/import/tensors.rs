//! The tensors of one entry of a PyTorch checkpoint, by name, checked as they are read.
//!
//! `torch.save` writes a zip of a pickle and raw storages; `pytorch-reader` parses the pickle
//! without running it and reads each storage on demand. A [`Source`] keeps the tensors under
//! one prefix (`model.ema_model.`, say) and hands out their values as f32 only after checking
//! the element type, the shape and that every value is finite, each failure naming the key.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use pytorch_reader::{DType, PickleValue, PytorchReader, Tensor};

use super::ImportError;

/// The tensors under one prefix of a checkpoint's top-level entry.
pub struct Source {
    path: PathBuf,
    /// Name without the prefix → tensor.
    tensors: BTreeMap<String, Tensor>,
    /// How the file names a key: `top` + `.` + `prefix` + name.
    shown: String,
}

impl Source {
    /// The tensors of `path`'s top-level entry `top` whose names start with `prefix` (kept
    /// without it); `top = None` reads the whole file (a plain state_dict).
    ///
    /// # Errors
    /// [`ImportError::Read`] for a file that is not a PyTorch checkpoint or lacks `top`;
    /// [`ImportError::Missing`] naming `prefix` when no tensor has it.
    pub fn open(path: &Path, top: Option<&str>, prefix: &str) -> Result<Self, ImportError> {
        let read = |source| ImportError::Read { path: path.to_path_buf(), source };
        let reader = match top {
            Some(t) => PytorchReader::with_top_level_key(path, t),
            None => PytorchReader::new(path),
        }
        .map_err(read)?;
        let tensors: BTreeMap<String, Tensor> = reader
            .into_tensors()
            .into_iter()
            .filter_map(|(name, t)| name.strip_prefix(prefix).map(|n| (n.to_string(), t)))
            .collect();
        let shown = top.map_or_else(|| prefix.to_string(), |t| format!("{t}.{prefix}"));
        if tensors.is_empty() {
            return Err(ImportError::Missing { path: path.to_path_buf(), key: format!("{shown}*") });
        }
        Ok(Self { path: path.to_path_buf(), tensors, shown })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// How the file names `key` (with its entry and prefix), for messages.
    pub fn shown(&self, key: &str) -> String {
        format!("{}{key}", self.shown)
    }

    /// Every tensor's name (without the prefix) and shape.
    pub fn shapes(&self) -> BTreeMap<String, Vec<usize>> {
        self.tensors.iter().map(|(n, t)| (n.clone(), t.shape().to_vec())).collect()
    }

    /// The names, without the prefix.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.tensors.keys().map(String::as_str)
    }

    /// The values of `key`, which must be float32 of shape `expected`, all finite.
    ///
    /// # Errors
    /// [`ImportError::Missing`], [`ImportError::DType`], [`ImportError::Shape`],
    /// [`ImportError::Io`] or [`ImportError::NonFinite`], naming the key.
    pub fn f32s(&self, key: &str, expected: &[usize]) -> Result<Vec<f32>, ImportError> {
        let path = self.path.clone();
        let shown = self.shown(key);
        let t = self
            .tensors
            .get(key)
            .ok_or_else(|| ImportError::Missing { path: path.clone(), key: shown.clone() })?;
        if t.dtype() != DType::F32 {
            return Err(ImportError::DType {
                path,
                key: shown,
                found: format!("{:?}", t.dtype()).to_lowercase(),
            });
        }
        if t.shape() != expected {
            return Err(ImportError::Shape {
                path,
                key: shown,
                found: t.shape().to_vec(),
                expected: expected.to_vec(),
            });
        }
        let bytes =
            t.read().map_err(|source| ImportError::Io { path: path.clone(), key: shown.clone(), source })?;
        let values: Vec<f32> =
            bytes.chunks_exact(4).map(|b| f32::from_ne_bytes([b[0], b[1], b[2], b[3]])).collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(ImportError::NonFinite { path, key: shown });
        }
        Ok(values)
    }
}

/// The integer at `path`'s top-level entry `key` (a training step), if it has one.
pub fn top_level_int(path: &Path, key: &str) -> Option<i64> {
    match PytorchReader::read_pickle_data(path, Some(key)) {
        Ok(PickleValue::Int(v)) => Some(v),
        _ => None,
    }
}
