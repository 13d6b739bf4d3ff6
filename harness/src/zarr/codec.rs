//! Chunk decoding and fill values of the zarr reader: the compressors it reads
//! (none, zlib, gzip, blosc) bounded by the chunk's size, so a damaged chunk is an
//! error rather than an allocation without limit.

use std::io::Read;
use std::path::Path;

use serde_json::Value;

use super::{DType, ZarrError};

/// One element of `dtype` holding the JSON fill value `v` (a number, or zarr's
/// `"NaN"` / `"Infinity"` / `"-Infinity"` for floats), little-endian.
pub(super) fn fill_bytes(dtype: DType, v: &Value) -> Option<Vec<u8>> {
    let float = || match v.as_str() {
        Some("NaN") => Some(f64::NAN),
        Some("Infinity") => Some(f64::INFINITY),
        Some("-Infinity") => Some(f64::NEG_INFINITY),
        _ => v.as_f64(),
    };
    match dtype {
        DType::U8 => v.as_u64().and_then(|x| u8::try_from(x).ok()).map(|x| vec![x]),
        DType::I64 => v.as_i64().map(|x| x.to_le_bytes().to_vec()),
        DType::F32 => float().map(|x| (x as f32).to_le_bytes().to_vec()),
        DType::F64 => float().map(|x| x.to_le_bytes().to_vec()),
    }
}

pub(super) fn decode(
    path: &Path,
    bytes: &[u8],
    compressor: Option<&Value>,
    expected: usize,
) -> Result<Vec<u8>, ZarrError> {
    let corrupt = |m: String| ZarrError::Corrupt { path: path.to_path_buf(), message: m };
    let Some(c) = compressor.filter(|c| !c.is_null()) else {
        return Ok(bytes.to_vec());
    };
    let id = c.get("id").and_then(Value::as_str).unwrap_or("");
    let mut out = Vec::with_capacity(expected);
    match id {
        // Decoders stop one byte past the expected size: a damaged chunk that would
        // inflate without bound is refused by the caller's size check instead.
        "zlib" => {
            flate2::read::ZlibDecoder::new(bytes)
                .take(expected as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| corrupt(e.to_string()))?;
        }
        "gzip" => {
            flate2::read::GzDecoder::new(bytes)
                .take(expected as u64 + 1)
                .read_to_end(&mut out)
                .map_err(|e| corrupt(e.to_string()))?;
        }
        "blosc" => {
            // The header's uncompressed size (bytes 4..8) must be the chunk's, before
            // anything of that size is allocated.
            let declared = bytes.get(4..8).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
            if declared != Some(expected) {
                let declared =
                    declared.map_or_else(|| "no size (truncated)".to_string(), |d| format!("{d} bytes"));
                return Err(corrupt(format!("blosc header declares {declared}, expected {expected} bytes")));
            }
            out = crate::blosc::decompress(bytes)
                .map_err(|source| ZarrError::Blosc { path: path.to_path_buf(), source })?;
        }
        other => {
            return Err(ZarrError::Unsupported {
                path: path.to_path_buf(),
                what: format!("compressor '{other}'"),
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::{ArrayReader, ArrayWriter};
    use super::*;

    /// A 1-D f32 array of 6 rows in chunks of 2, its `.zarray` given `fill`.
    fn array(dir: &Path, fill: Value) -> ArrayReader {
        let mut w = ArrayWriter::create(dir, DType::F32, &[], 2).unwrap();
        w.append(&(1..=6u8).flat_map(|i| f32::from(i).to_le_bytes()).collect::<Vec<u8>>()).unwrap();
        w.finish().unwrap();
        let meta = dir.join(".zarray");
        let mut m: Value = serde_json::from_slice(&std::fs::read(&meta).unwrap()).unwrap();
        assert!(m["fill_value"].is_null(), "evalharness writes no fill value: {m}");
        m["fill_value"] = fill;
        std::fs::write(&meta, m.to_string()).unwrap();
        std::fs::remove_file(dir.join("1")).unwrap(); // rows 2 and 3
        ArrayReader::open(dir).unwrap()
    }

    #[test]
    fn a_missing_chunk_is_an_error_unless_a_fill_value_is_declared() {
        let tmp = tempfile::tempdir().unwrap();
        let err = array(&tmp.path().join("a"), Value::Null).read_f64().unwrap_err().to_string();
        assert!(err.contains("chunk '1' is missing"), "{err}");
        // A foreign array that declares a fill value reads it there (rows 2, 3).
        let b = array(&tmp.path().join("b"), serde_json::json!(-1.5));
        assert_eq!(b.read_f64().unwrap(), vec![1.0, 2.0, -1.5, -1.5, 5.0, 6.0]);
        // ... unless its writer is known to write every chunk.
        assert!(b.all_chunks_written().read_f64().is_err());
        let c = array(&tmp.path().join("c"), serde_json::json!("NaN"));
        assert!(c.read_f64().unwrap()[2].is_nan());
    }

    #[test]
    fn fill_values_take_the_array_type() {
        assert_eq!(fill_bytes(DType::U8, &serde_json::json!(7)), Some(vec![7]));
        assert_eq!(fill_bytes(DType::U8, &serde_json::json!(300)), None);
        assert_eq!(fill_bytes(DType::F64, &serde_json::json!(0.5)), Some(0.5f64.to_le_bytes().to_vec()));
        assert_eq!(fill_bytes(DType::I64, &serde_json::json!("x")), None);
    }

    #[test]
    fn a_blosc_header_of_the_wrong_size_is_refused_before_decoding() {
        // A 16-byte header declaring 4 GiB - 1 bytes for a 12-byte chunk.
        let mut frame = vec![2u8, 1, 0x21, 4];
        frame.extend(u32::MAX.to_le_bytes());
        frame.extend(12u32.to_le_bytes());
        frame.extend(16u32.to_le_bytes());
        let blosc = serde_json::json!({"id": "blosc"});
        let err = decode(Path::new("x/0"), &frame, Some(&blosc), 12).unwrap_err().to_string();
        assert!(err.contains("declares 4294967295 bytes, expected 12"), "{err}");
    }
}
