//! The tensors of a `.safetensors` file (LeRobot's `model.safetensors` and its processors'
//! statistics), by name, checked as they are read: the same contract as [`super::tensors`]
//! (float32, the expected shape, every value finite, each failure naming the file and key).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors};

use super::ImportError;

/// A safetensors file's tensors.
pub struct SafeSource {
    path: PathBuf,
    bytes: Vec<u8>,
    /// Name → (element type, shape).
    index: BTreeMap<String, (Dtype, Vec<usize>)>,
}

impl SafeSource {
    /// Reads and indexes `path`.
    ///
    /// # Errors
    /// [`ImportError::Io`] for an unreadable file, [`ImportError::Layout`] for one that is not
    /// a safetensors file.
    pub fn open(path: &Path) -> Result<Self, ImportError> {
        let bytes = std::fs::read(path).map_err(|source| ImportError::Io {
            path: path.into(),
            key: "(the file)".into(),
            source,
        })?;
        let st = SafeTensors::deserialize(&bytes).map_err(|e| ImportError::Layout {
            path: path.into(),
            what: format!("not a safetensors file: {e}"),
        })?;
        let index = st.tensors().into_iter().map(|(n, v)| (n, (v.dtype(), v.shape().to_vec()))).collect();
        Ok(Self { path: path.into(), bytes, index })
    }

    /// The file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Every tensor's name and shape.
    pub fn shapes(&self) -> BTreeMap<String, Vec<usize>> {
        self.index.iter().map(|(n, (_, s))| (n.clone(), s.clone())).collect()
    }

    /// Whether the file has `key`.
    pub fn has(&self, key: &str) -> bool {
        self.index.contains_key(key)
    }

    /// The shape of `key`, which must be of type `want`.
    fn typed(&self, key: &str, want: Dtype) -> Result<&[usize], ImportError> {
        let (dtype, shape) = self
            .index
            .get(key)
            .ok_or_else(|| ImportError::Missing { path: self.path.clone(), key: key.into() })?;
        if *dtype != want {
            return Err(ImportError::DType {
                path: self.path.clone(),
                key: key.into(),
                found: format!("{dtype:?}").to_lowercase(),
            });
        }
        Ok(shape)
    }

    /// The raw little-endian bytes of `key`.
    fn bytes_of(&self, key: &str) -> Result<Vec<u8>, ImportError> {
        let layout = |what: String| ImportError::Layout { path: self.path.clone(), what };
        let st = SafeTensors::deserialize(&self.bytes)
            .map_err(|e| layout(format!("not a safetensors file: {e}")))?;
        let view = st.tensor(key).map_err(|e| layout(format!("key `{key}`: {e}")))?;
        Ok(view.data().to_vec())
    }

    /// The values of `key`, which must be float32 holding `expected.iter().product()` values
    /// (any shape of that size when `flat`; else exactly `expected`), all finite.
    ///
    /// # Errors
    /// [`ImportError::Missing`], [`ImportError::DType`], [`ImportError::Shape`] or
    /// [`ImportError::NonFinite`], naming the key.
    pub fn f32s(&self, key: &str, expected: &[usize], flat: bool) -> Result<Vec<f32>, ImportError> {
        let shape = self.typed(key, Dtype::F32)?;
        let fits = if flat {
            shape.iter().product::<usize>() == expected.iter().product::<usize>()
        } else {
            shape == expected
        };
        if !fits {
            return Err(ImportError::Shape {
                path: self.path.clone(),
                key: key.into(),
                found: shape.to_vec(),
                expected: expected.to_vec(),
            });
        }
        let values: Vec<f32> = self
            .bytes_of(key)?
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(ImportError::NonFinite { path: self.path.clone(), key: key.into() });
        }
        Ok(values)
    }

    /// The bytes of `key`, which must be uint8 (frames).
    ///
    /// # Errors
    /// [`ImportError::Missing`] or [`ImportError::DType`], naming the key.
    pub fn u8s(&self, key: &str) -> Result<Vec<u8>, ImportError> {
        self.typed(key, Dtype::U8)?;
        self.bytes_of(key)
    }
}
