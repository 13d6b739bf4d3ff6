//! One per-step array of a dataset (`data/img`, `data/action`, `data/state`) seen as one
//! array across the zarr groups it is stored in: a dataset is one group, or a folder of
//! groups read in name order as GPC stores its world-model data. Rows are numbered through
//! the groups; a read may span them.
//!
//! Images are bytes. GPC's data may store them as float32 in [0, 255]; those are rounded to
//! the nearest byte on reading, and a value outside [0, 255] (or not finite) is refused
//! naming the group's array and row, so an image stored in [0, 1] is not read as black.

use std::path::PathBuf;

use crate::zarr::{ArrayReader, DType, bytes_to_f64};

use super::ReplayError;

/// One array across the groups of a dataset.
#[derive(Clone, Debug)]
pub struct Column {
    parts: Vec<ArrayReader>,
    /// The first row of each part, then the total.
    starts: Vec<usize>,
    /// Rows are images, read as bytes whatever the stored type.
    image: bool,
    /// The stored arrays, for errors.
    dirs: Vec<PathBuf>,
}

impl Column {
    /// The array stored in `parts` (one per group, in order); `dirs` name them in errors.
    /// The caller has checked that the parts' rows have one shape.
    pub fn new(parts: Vec<ArrayReader>, dirs: Vec<PathBuf>, image: bool) -> Self {
        let mut starts = vec![0];
        for p in &parts {
            starts.push(starts.last().copied().unwrap_or(0) + p.rows());
        }
        Self { parts, starts, image, dirs }
    }

    /// Rows in all parts.
    pub fn rows(&self) -> usize {
        self.starts.last().copied().unwrap_or(0)
    }

    /// Elements per row.
    pub fn row_len(&self) -> usize {
        self.parts.first().map_or(0, ArrayReader::row_len)
    }

    /// The shape: all rows, then a row's shape (`[N, H, W, 3]` for images).
    pub fn shape(&self) -> Vec<usize> {
        let mut s = self.parts.first().map_or_else(Vec::new, |p| p.meta.shape.clone());
        if let Some(n) = s.first_mut() {
            *n = self.rows();
        }
        s
    }

    /// The parts rows `[start, end)` fall in, with each part's local range.
    fn pieces(&self, start: usize, end: usize) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        let end = end.min(self.rows());
        (0..self.parts.len()).filter_map(move |k| {
            let (lo, hi) = (start.max(self.starts[k]), end.min(self.starts[k + 1]));
            (lo < hi).then(|| (k, lo - self.starts[k], hi - self.starts[k]))
        })
    }

    /// Rows `[start, end)`: little-endian bytes of the stored type, or, for images, one
    /// byte per element.
    ///
    /// # Errors
    /// [`ReplayError`] for unreadable chunks, or an image value outside [0, 255].
    pub fn read_rows(&self, start: usize, end: usize) -> Result<Vec<u8>, ReplayError> {
        let mut out = Vec::new();
        for (k, lo, hi) in self.pieces(start, end) {
            let part = &self.parts[k];
            let raw = part.read_rows(lo, hi)?;
            if !self.image || part.dtype == DType::U8 {
                out.extend_from_slice(&raw);
                continue;
            }
            let row_len = part.row_len().max(1);
            for (i, v) in bytes_to_f64(&raw, part.dtype).into_iter().enumerate() {
                if !(v.is_finite() && (0.0..=255.0).contains(&v)) {
                    return Err(ReplayError::Layout {
                        path: self.dirs[k].clone(),
                        reason: format!(
                            "row {} holds {v}: images are read as bytes, stored as uint8 or as floats in [0, 255]",
                            lo + i / row_len
                        ),
                    });
                }
                out.push(v.round() as u8);
            }
        }
        Ok(out)
    }

    /// Rows `[start, end)` as f64 values.
    ///
    /// # Errors
    /// As [`Column::read_rows`].
    pub fn read_rows_f64(&self, start: usize, end: usize) -> Result<Vec<f64>, ReplayError> {
        if self.image {
            return Ok(self.read_rows(start, end)?.into_iter().map(f64::from).collect());
        }
        let mut out = Vec::new();
        for (k, lo, hi) in self.pieces(start, end) {
            let part = &self.parts[k];
            out.extend(bytes_to_f64(&part.read_rows(lo, hi)?, part.dtype));
        }
        Ok(out)
    }

    /// Every row as f64 values.
    ///
    /// # Errors
    /// As [`Column::read_rows`].
    pub fn read_f64(&self) -> Result<Vec<f64>, ReplayError> {
        self.read_rows_f64(0, self.rows())
    }
}
