//! A decoder for Blosc1 frames, zarr-python's default compressor.
//!
//! Existing Push-T replay buffers (diffusion_policy, GPC) were written by
//! zarr-python, whose default is `Blosc(cname="lz4", clevel=5, shuffle=1)`.
//! This module reads such chunks: the 16-byte header, the block-start table,
//! per-block streams (split per byte of the type unless the "don't split" flag
//! is set or the block is the last, partial one), the lz4 or zlib codecs, and
//! byte un-shuffling. Bit-shuffle and the blosclz/snappy/zstd codecs are
//! reported as unsupported rather than guessed at.

use std::io::Read;

const HEADER: usize = 16;
const FLAG_SHUFFLE: u8 = 0x01;
const FLAG_MEMCPYED: u8 = 0x02;
const FLAG_BITSHUFFLE: u8 = 0x04;
const FLAG_DONT_SPLIT: u8 = 0x10;

/// Why a Blosc1 frame cannot be decoded.
#[derive(Debug, thiserror::Error)]
pub enum BloscError {
    /// The frame ends before what its header or tables say it holds.
    #[error("truncated blosc frame: {0}")]
    Truncated(String),
    /// A feature this decoder does not implement (bit-shuffle, a codec).
    #[error("blosc {0} is not supported")]
    Unsupported(String),
    /// A block whose compressed stream does not decode.
    #[error("{codec}: {message}")]
    Codec {
        /// `lz4` or `zlib`.
        codec: &'static str,
        /// The codec's message.
        message: String,
    },
    /// A block that decoded to another size than the header says, or a block size of 0.
    #[error("blosc {0}")]
    Size(String),
}

fn u32_at(b: &[u8], at: usize) -> Result<usize, BloscError> {
    b.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]) as usize)
        .ok_or_else(|| BloscError::Truncated(format!("at byte {at}")))
}

/// Decompresses one Blosc1 frame.
///
/// # Errors
/// [`BloscError`]: a truncated frame, an unsupported feature or a codec failure.
pub fn decompress(frame: &[u8]) -> Result<Vec<u8>, BloscError> {
    if frame.len() < HEADER {
        return Err(BloscError::Truncated("shorter than its header".into()));
    }
    let flags = frame[2];
    let typesize = usize::from(frame[3]).max(1);
    let nbytes = u32_at(frame, 4)?;
    let blocksize = u32_at(frame, 8)?;
    if flags & FLAG_MEMCPYED != 0 {
        return frame
            .get(HEADER..HEADER + nbytes)
            .map(<[u8]>::to_vec)
            .ok_or_else(|| BloscError::Truncated("a memcpyed frame".into()));
    }
    if flags & FLAG_BITSHUFFLE != 0 && flags & FLAG_SHUFFLE == 0 {
        return Err(BloscError::Unsupported("bit-shuffle".into()));
    }
    let codec = flags >> 5;
    if codec != 1 && codec != 3 {
        let name = ["blosclz", "lz4", "snappy", "zlib", "zstd"].get(usize::from(codec)).unwrap_or(&"unknown");
        return Err(BloscError::Unsupported(format!("codec '{name}' (lz4 and zlib are)")));
    }
    if blocksize == 0 {
        return Err(BloscError::Size("block size 0".into()));
    }
    let nblocks = nbytes.div_ceil(blocksize);
    let mut out = vec![0u8; nbytes];
    for j in 0..nblocks {
        let start = u32_at(frame, HEADER + 4 * j)?;
        let bsize = blocksize.min(nbytes - j * blocksize);
        let leftover = bsize < blocksize;
        let nstreams = if flags & FLAG_DONT_SPLIT == 0 && !leftover { typesize } else { 1 };
        let neblock = bsize / nstreams;
        let mut block = Vec::with_capacity(bsize);
        let mut at = start;
        for _ in 0..nstreams {
            let csize = u32_at(frame, at)?;
            at += 4;
            let data = frame
                .get(at..at + csize)
                .ok_or_else(|| BloscError::Truncated(format!("a stream at byte {at}")))?;
            at += csize;
            if csize == neblock {
                block.extend_from_slice(data);
            } else if codec == 1 {
                let dec = lz4_flex::block::decompress(data, neblock)
                    .map_err(|e| BloscError::Codec { codec: "lz4", message: e.to_string() })?;
                block.extend_from_slice(&dec);
            } else {
                let mut dec = Vec::with_capacity(neblock);
                flate2::read::ZlibDecoder::new(data)
                    .read_to_end(&mut dec)
                    .map_err(|e| BloscError::Codec { codec: "zlib", message: e.to_string() })?;
                block.extend_from_slice(&dec);
            }
        }
        if block.len() != bsize {
            return Err(BloscError::Size(format!(
                "block {j} decoded to {} bytes, expected {bsize}",
                block.len()
            )));
        }
        let dst = &mut out[j * blocksize..j * blocksize + bsize];
        if flags & FLAG_SHUFFLE != 0 && typesize > 1 {
            unshuffle(&block, typesize, dst);
        } else {
            dst.copy_from_slice(&block);
        }
    }
    Ok(out)
}

/// Inverse of Blosc's byte shuffle: `src` holds byte k of every element, then byte k+1...
fn unshuffle(src: &[u8], typesize: usize, dst: &mut [u8]) {
    let nel = src.len() / typesize;
    for i in 0..nel {
        for k in 0..typesize {
            dst[i * typesize + k] = src[k * nel + i];
        }
    }
    let tail = nel * typesize;
    dst[tail..].copy_from_slice(&src[tail..]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unshuffle_interleaves_bytes() {
        // Two u16 elements 0x0201 and 0x0403, shuffled: low bytes [01 03], high [02 04].
        let mut dst = [0u8; 4];
        unshuffle(&[1, 3, 2, 4], 2, &mut dst);
        assert_eq!(dst, [1, 2, 3, 4]);
    }

    #[test]
    fn memcpyed_frame_is_copied() {
        let mut f = vec![2, 1, FLAG_MEMCPYED, 1];
        f.extend_from_slice(&3u32.to_le_bytes());
        f.extend_from_slice(&3u32.to_le_bytes());
        f.extend_from_slice(&19u32.to_le_bytes());
        f.extend_from_slice(&[7, 8, 9]);
        assert_eq!(decompress(&f).unwrap(), vec![7, 8, 9]);
    }

    #[test]
    fn truncated_frame_is_an_error() {
        let e = decompress(&[2, 1, 0]).unwrap_err();
        assert_eq!(e.to_string(), "truncated blosc frame: shorter than its header");
        // A header saying 3 memcpyed bytes, with none after it.
        let mut f = vec![2, 1, FLAG_MEMCPYED, 1];
        f.extend_from_slice(&3u32.to_le_bytes());
        f.extend_from_slice(&3u32.to_le_bytes());
        f.extend_from_slice(&19u32.to_le_bytes());
        assert!(matches!(decompress(&f), Err(BloscError::Truncated(_))));
        // zstd (codec 4, the flags' top three bits) is named, not guessed at.
        let mut z = vec![2, 1, 4 << 5, 1];
        z.extend_from_slice(&[0; 12]);
        assert_eq!(
            decompress(&z).unwrap_err().to_string(),
            "blosc codec 'zstd' (lz4 and zlib are) is not supported"
        );
    }
}
