//! Reading other code's checkpoints, shared by every importer (the world model's, the
//! policies' and the judges'), so that nothing past an import parses a foreign file.
//!
//! - [`tensors`]: reading a `.pth` file's tensors by name with `pytorch-reader` (a zip and
//!   pickle reader that runs no code), checking each one's type, shape and values;
//!   [`safe`]: the same for `.safetensors` files (LeRobot's), with the `safetensors` crate.
//!
//! An import refuses a missing, unexpected or mis-shaped key, a tensor that is not float32 and
//! a non-finite value, naming the key; nothing is written then (the binary stages the output).
//! [`place`] puts converted tensors into a burn module by name.

pub mod place;
pub mod safe;
pub mod tensors;

use std::path::PathBuf;

/// Why a file cannot be imported: each variant names the file and, where there is one, the key.
#[derive(Debug, thiserror::Error)]
pub enum ImportError {
    /// Not a readable PyTorch file, or without the expected top-level entry.
    #[error("{path}: cannot be read as a PyTorch checkpoint: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The reader's error.
        #[source]
        source: pytorch_reader::PytorchError,
    },
    /// A key the architecture needs is absent.
    #[error("{path}: key `{key}` is missing")]
    Missing {
        /// The file.
        path: PathBuf,
        /// The key, as the file names it.
        key: String,
    },
    /// Keys the architecture has no place for.
    #[error("{path}: unexpected key(s) {}", keys.join(", "))]
    Unexpected {
        /// The file.
        path: PathBuf,
        /// The keys, sorted.
        keys: Vec<String>,
    },
    /// A tensor of the wrong shape.
    #[error("{path}: key `{key}` has shape {found:?}, expected {expected:?}")]
    Shape {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// Its shape in the file.
        found: Vec<usize>,
        /// The shape the architecture needs.
        expected: Vec<usize>,
    },
    /// A tensor that is not float32.
    #[error("{path}: key `{key}` is {found}; only float32 weights are imported")]
    DType {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// Its element type.
        found: String,
    },
    /// A tensor holding NaN or an infinity.
    #[error("{path}: key `{key}` holds a non-finite value")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
    },
    /// A tensor whose bytes cannot be read.
    #[error("{path}: reading key `{key}`: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The key.
        key: String,
        /// The reader's error.
        #[source]
        source: std::io::Error,
    },
    /// Shapes that fit no network of the format (a file of another model).
    #[error("{path}: {what}")]
    Layout {
        /// The file.
        path: PathBuf,
        /// What does not fit, naming the keys involved.
        what: String,
    },
    /// The converted weights could not be placed in the network (a bug, not a bad file).
    #[error("{path}: placing the converted weights: {what}")]
    Apply {
        /// The file.
        path: PathBuf,
        /// What failed.
        what: String,
    },
}
