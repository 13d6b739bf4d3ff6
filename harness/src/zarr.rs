//! A minimal zarr v2 directory store: what the replay-buffer datasets need.
//!
//! Arrays are chunked along their first axis only (the layout diffusion_policy
//! and GPC use: `data/img` chunks of whole frames). Writing uses the `zlib`
//! codec, which zarr-python reads out of the box; reading accepts no
//! compressor, `zlib`, `gzip` and `blosc` with the lz4 or zlib codec and byte or
//! no shuffle (zarr-python's default is blosc-lz4 with byte shuffle), so zarr
//! files made by those projects load here and ours load there.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

mod codec;
use codec::{decode, fill_bytes};

/// Errors of the zarr store, each naming the array or file.
#[derive(Debug, thiserror::Error)]
pub enum ZarrError {
    /// I/O on a file of the store.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Metadata that is not valid zarr v2 JSON.
    #[error("{path}: invalid zarr metadata: {message}")]
    Meta {
        /// The metadata file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A feature of the file this reader does not implement.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The array.
        path: PathBuf,
        /// What it uses.
        what: String,
    },
    /// A chunk file that is not there, in an array whose chunks are all written.
    #[error(
        "{array}: chunk '{key}' is missing (the array has no fill value for missing chunks; the dataset is incomplete)"
    )]
    MissingChunk {
        /// The array folder.
        array: PathBuf,
        /// The chunk key (its file name).
        key: String,
    },
    /// A chunk that does not decode to the expected size.
    #[error("{path}: corrupt chunk: {message}")]
    Corrupt {
        /// The chunk file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A Blosc-compressed chunk that does not decode.
    #[error("{path}: corrupt chunk: {source}")]
    Blosc {
        /// The chunk file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: crate::blosc::BloscError,
    },
}

/// The largest chunk this reader decodes (1 GiB; evalharness writes ~2.8 MB image
/// chunks).
pub const MAX_CHUNK_BYTES: usize = 1 << 30;

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> ZarrError + '_ {
    move |source| ZarrError::Io { path: path.to_path_buf(), source }
}

/// Element types this store reads and writes (little-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DType {
    /// `|u1`
    U8,
    /// `<f4`
    F32,
    /// `<f8`
    F64,
    /// `<i8`
    I64,
}

impl DType {
    /// Bytes per element.
    pub fn size(self) -> usize {
        match self {
            DType::U8 => 1,
            DType::F32 => 4,
            DType::F64 | DType::I64 => 8,
        }
    }

    /// The numpy type string.
    pub fn code(self) -> &'static str {
        match self {
            DType::U8 => "|u1",
            DType::F32 => "<f4",
            DType::F64 => "<f8",
            DType::I64 => "<i8",
        }
    }

    fn parse(code: &str) -> Option<Self> {
        match code {
            "|u1" | "<u1" => Some(DType::U8),
            "<f4" => Some(DType::F32),
            "<f8" => Some(DType::F64),
            "<i8" => Some(DType::I64),
            _ => None,
        }
    }
}

/// The `.zarray` document.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ArrayMeta {
    /// Array shape.
    pub shape: Vec<usize>,
    /// Chunk shape.
    pub chunks: Vec<usize>,
    /// numpy dtype string.
    pub dtype: String,
    /// Compressor config (`null` for none).
    pub compressor: Option<Value>,
    /// Fill value for missing chunks.
    pub fill_value: Option<Value>,
    /// Filters (must be null).
    pub filters: Option<Value>,
    /// Memory order (must be "C").
    pub order: String,
    /// Always 2.
    pub zarr_format: u32,
    /// Chunk key separator ("." by default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dimension_separator: Option<String>,
}

/// Creates a group folder with its `.zgroup` (and `.zattrs` when given).
///
/// # Errors
/// [`ZarrError::Io`] naming the file that could not be written.
pub fn write_group(dir: &Path, attrs: Option<&Value>) -> Result<(), ZarrError> {
    fs::create_dir_all(dir).map_err(io(dir))?;
    let g = dir.join(".zgroup");
    fs::write(&g, b"{\n    \"zarr_format\": 2\n}").map_err(io(&g))?;
    if let Some(a) = attrs {
        let p = dir.join(".zattrs");
        fs::write(&p, serde_json::to_vec_pretty(a).unwrap_or_default()).map_err(io(&p))?;
    }
    Ok(())
}

/// Reads a group's `.zattrs` (an empty object when absent).
///
/// # Errors
/// [`ZarrError::Meta`] when the file is not JSON.
pub fn read_attrs(dir: &Path) -> Result<Value, ZarrError> {
    let p = dir.join(".zattrs");
    match fs::read(&p) {
        Ok(bytes) => {
            serde_json::from_slice(&bytes).map_err(|e| ZarrError::Meta { path: p, message: e.to_string() })
        }
        Err(_) => Ok(json!({})),
    }
}

/// Streams an array to disk chunk by chunk along its first axis.
///
/// Rows are appended with [`ArrayWriter::append`]; full chunks are compressed and
/// written as they fill; [`ArrayWriter::finish`] writes the last (zero-padded)
/// chunk and only then the `.zarray`, so an interrupted write is not a valid array.
pub struct ArrayWriter {
    dir: PathBuf,
    dtype: DType,
    row_shape: Vec<usize>,
    chunk_rows: usize,
    buf: Vec<u8>,
    rows: usize,
    next_chunk: usize,
}

impl ArrayWriter {
    /// A writer for array `dir` with rows of `row_shape` elements, `chunk_rows` rows a chunk.
    ///
    /// # Errors
    /// [`ZarrError::Io`] when the folder cannot be created.
    pub fn create(
        dir: &Path,
        dtype: DType,
        row_shape: &[usize],
        chunk_rows: usize,
    ) -> Result<Self, ZarrError> {
        fs::create_dir_all(dir).map_err(io(dir))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            dtype,
            row_shape: row_shape.to_vec(),
            chunk_rows: chunk_rows.max(1),
            buf: Vec::new(),
            rows: 0,
            next_chunk: 0,
        })
    }

    fn row_bytes(&self) -> usize {
        self.row_shape.iter().product::<usize>() * self.dtype.size()
    }

    /// Appends whole rows given as little-endian bytes.
    ///
    /// # Errors
    /// [`ZarrError::Io`] when a chunk cannot be written.
    ///
    /// # Panics
    /// If `bytes` is not a whole number of rows (a programming error).
    pub fn append(&mut self, bytes: &[u8]) -> Result<(), ZarrError> {
        let rb = self.row_bytes();
        assert!(
            rb == 0 || bytes.len().is_multiple_of(rb),
            "append: {} bytes is not whole rows of {rb}",
            bytes.len()
        );
        self.buf.extend_from_slice(bytes);
        self.rows += bytes.len().checked_div(rb).unwrap_or(0);
        let chunk_bytes = rb * self.chunk_rows;
        while self.buf.len() >= chunk_bytes && chunk_bytes > 0 {
            let rest = self.buf.split_off(chunk_bytes);
            let chunk = std::mem::replace(&mut self.buf, rest);
            self.write_chunk(&chunk)?;
        }
        Ok(())
    }

    fn write_chunk(&mut self, raw: &[u8]) -> Result<(), ZarrError> {
        let mut key = self.next_chunk.to_string();
        for _ in &self.row_shape {
            key.push_str(".0");
        }
        let path = self.dir.join(key);
        let mut enc = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(3));
        enc.write_all(raw).map_err(io(&path))?;
        let bytes = enc.finish().map_err(io(&path))?;
        fs::write(&path, bytes).map_err(io(&path))?;
        self.next_chunk += 1;
        Ok(())
    }

    /// Rows appended so far.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// Writes the last chunk and the `.zarray`.
    ///
    /// # Errors
    /// [`ZarrError::Io`] when a file cannot be written.
    pub fn finish(mut self) -> Result<(), ZarrError> {
        if !self.buf.is_empty() {
            let mut last = std::mem::take(&mut self.buf);
            last.resize(self.row_bytes() * self.chunk_rows, 0);
            self.write_chunk(&last)?;
        }
        let mut shape = vec![self.rows];
        shape.extend(&self.row_shape);
        let mut chunks = vec![self.chunk_rows];
        chunks.extend(&self.row_shape);
        let meta = ArrayMeta {
            shape,
            chunks,
            dtype: self.dtype.code().into(),
            compressor: Some(json!({"id": "zlib", "level": 3})),
            // Every chunk is written: a missing one means a damaged store, not zeros.
            fill_value: None,
            filters: None,
            order: "C".into(),
            zarr_format: 2,
            dimension_separator: None,
        };
        let p = self.dir.join(".zarray");
        fs::write(&p, serde_json::to_vec_pretty(&meta).unwrap_or_default()).map_err(io(&p))
    }
}

/// An array opened for reading.
///
/// A chunk file that is not there is an error ([`ZarrError::MissingChunk`]) unless the
/// array declares a fill value and its writer may omit chunks: then the chunk reads as
/// that value, with a warning naming it. evalharness's own writer writes every chunk,
/// so its datasets are read with [`ArrayReader::all_chunks_written`], and writes
/// `fill_value: null`.
#[derive(Clone, Debug)]
pub struct ArrayReader {
    dir: PathBuf,
    /// Its metadata.
    pub meta: ArrayMeta,
    /// Its element type.
    pub dtype: DType,
    /// The bytes of one element of the fill value; `None`: a missing chunk is an error.
    fill: Option<Vec<u8>>,
}

impl ArrayReader {
    /// Opens array `dir` and checks that this reader supports it.
    ///
    /// # Errors
    /// [`ZarrError::Io`]/[`ZarrError::Meta`] for a missing or invalid `.zarray`,
    /// [`ZarrError::Unsupported`] for dtypes, orders, filters or chunkings it does not read.
    pub fn open(dir: &Path) -> Result<Self, ZarrError> {
        let p = dir.join(".zarray");
        let bytes = fs::read(&p).map_err(io(&p))?;
        let meta: ArrayMeta = serde_json::from_slice(&bytes)
            .map_err(|e| ZarrError::Meta { path: p.clone(), message: e.to_string() })?;
        let unsupported = |what: String| ZarrError::Unsupported { path: dir.to_path_buf(), what };
        let dtype = DType::parse(&meta.dtype).ok_or_else(|| unsupported(format!("dtype {}", meta.dtype)))?;
        if meta.order != "C" || meta.filters.as_ref().is_some_and(|f| !f.is_null()) {
            return Err(unsupported("Fortran order or filters".into()));
        }
        if meta.shape.is_empty()
            || meta.chunks.len() != meta.shape.len()
            || meta.chunks[1..] != meta.shape[1..]
        {
            return Err(unsupported(format!(
                "chunks {:?} for shape {:?} (only first-axis chunking)",
                meta.chunks, meta.shape
            )));
        }
        // A chunk is decoded whole: refuse metadata whose chunk would not fit in memory
        // (a damaged `.zarray`) before anything is allocated for it.
        let chunk_bytes = meta
            .chunks
            .iter()
            .try_fold(dtype.size(), |acc, &d| acc.checked_mul(d))
            .filter(|&b| b <= MAX_CHUNK_BYTES);
        let rows_fit = meta.shape.iter().try_fold(dtype.size(), |acc, &d| acc.checked_mul(d)).is_some();
        if chunk_bytes.is_none() || !rows_fit || meta.chunks[0] == 0 {
            return Err(unsupported(format!(
                "chunks {:?} of shape {:?}: a chunk must hold 1 to {MAX_CHUNK_BYTES} bytes",
                meta.chunks, meta.shape
            )));
        }
        let fill = match meta.fill_value.as_ref().filter(|v| !v.is_null()) {
            None => None,
            Some(v) => Some(fill_bytes(dtype, v).ok_or_else(|| ZarrError::Meta {
                path: p.clone(),
                message: format!("fill_value {v} is not a {} value", dtype.code()),
            })?),
        };
        Ok(Self { dir: dir.to_path_buf(), meta, dtype, fill })
    }

    /// The same array, read as one whose writer never omits a chunk: a missing chunk is
    /// an error whatever its fill value says.
    #[must_use]
    pub fn all_chunks_written(mut self) -> Self {
        self.fill = None;
        self
    }

    /// Number of rows (first axis).
    pub fn rows(&self) -> usize {
        self.meta.shape[0]
    }

    /// Elements per row.
    pub fn row_len(&self) -> usize {
        self.meta.shape[1..].iter().product()
    }

    /// Reads rows `[start, end)` as little-endian bytes.
    ///
    /// # Errors
    /// [`ZarrError`] for unreadable or corrupt chunks.
    pub fn read_rows(&self, start: usize, end: usize) -> Result<Vec<u8>, ZarrError> {
        let end = end.min(self.rows());
        let rb = self.row_len() * self.dtype.size();
        let cr = self.meta.chunks[0].max(1);
        let mut out = Vec::with_capacity((end.saturating_sub(start)) * rb);
        let sep = self.meta.dimension_separator.as_deref().unwrap_or(".");
        let mut row = start;
        while row < end {
            let c = row / cr;
            let mut key = c.to_string();
            for _ in 1..self.meta.shape.len() {
                key.push_str(sep);
                key.push('0');
            }
            let path = self.dir.join(&key);
            let raw = match fs::read(&path) {
                Ok(bytes) => decode(&path, &bytes, self.meta.compressor.as_ref(), rb * cr)?,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => match &self.fill {
                    None => return Err(ZarrError::MissingChunk { array: self.dir.clone(), key }),
                    Some(one) => {
                        tracing::warn!(
                            array = %self.dir.display(),
                            chunk = %key,
                            "chunk missing: read as the array's fill value"
                        );
                        one.repeat(rb * cr / one.len().max(1))
                    }
                },
                Err(e) => return Err(ZarrError::Io { path, source: e }),
            };
            if raw.len() != rb * cr {
                return Err(ZarrError::Corrupt {
                    path,
                    message: format!("decoded {} bytes, expected {}", raw.len(), rb * cr),
                });
            }
            let lo = row - c * cr;
            let hi = (end - c * cr).min(cr);
            out.extend_from_slice(&raw[lo * rb..hi * rb]);
            row = c * cr + hi;
        }
        Ok(out)
    }

    /// Reads the whole array as f64 values (any numeric dtype).
    ///
    /// # Errors
    /// [`ZarrError`] for unreadable or corrupt chunks.
    pub fn read_f64(&self) -> Result<Vec<f64>, ZarrError> {
        let raw = self.read_rows(0, self.rows())?;
        Ok(bytes_to_f64(&raw, self.dtype))
    }
}

/// Converts little-endian bytes of `dtype` into f64 values.
pub fn bytes_to_f64(raw: &[u8], dtype: DType) -> Vec<f64> {
    let n = dtype.size();
    raw.chunks_exact(n)
        .map(|b| match dtype {
            DType::U8 => f64::from(b[0]),
            DType::F32 => f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            DType::F64 => f64::from_le_bytes(b.try_into().unwrap_or([0; 8])),
            DType::I64 => i64::from_le_bytes(b.try_into().unwrap_or([0; 8])) as f64,
        })
        .collect()
}
