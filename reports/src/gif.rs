//! Animated GIFs of rendered episodes.
//!
//! Frames are RGB byte buffers (`w x h x 3`); each is quantised to a 256-colour
//! palette (NeuQuant) and appended with a fixed delay. The GIF loops forever.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Errors while writing a GIF, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum GifError {
    /// The file could not be created or written.
    #[error("{path}: {message}")]
    Write {
        /// The GIF file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// A frame whose size does not match `w x h x 3`.
    #[error("{path}: frame {index} has {len} bytes, expected {expected}")]
    FrameSize {
        /// The GIF file.
        path: PathBuf,
        /// Frame index.
        index: usize,
        /// Its length.
        len: usize,
        /// `w * h * 3`.
        expected: usize,
    },
}

/// Writes `frames` (each `w x h` RGB) as a looping GIF, `delay_ms` per frame.
///
/// # Errors
/// [`GifError`] naming the file when a frame has the wrong size or writing fails.
pub fn write_gif(path: &Path, frames: &[Vec<u8>], w: u16, h: u16, delay_ms: u32) -> Result<(), GifError> {
    let expected = usize::from(w) * usize::from(h) * 3;
    let err =
        |e: &dyn std::fmt::Display| GifError::Write { path: path.to_path_buf(), message: e.to_string() };
    let file = File::create(path).map_err(|e| err(&e))?;
    let mut enc = gif::Encoder::new(BufWriter::new(file), w, h, &[]).map_err(|e| err(&e))?;
    enc.set_repeat(gif::Repeat::Infinite).map_err(|e| err(&e))?;
    for (index, rgb) in frames.iter().enumerate() {
        if rgb.len() != expected {
            return Err(GifError::FrameSize { path: path.to_path_buf(), index, len: rgb.len(), expected });
        }
        let mut frame = gif::Frame::from_rgb_speed(w, h, rgb, 10);
        frame.delay = u16::try_from(delay_ms / 10).unwrap_or(u16::MAX);
        enc.write_frame(&frame).map_err(|e| err(&e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gif_round_trip_has_all_frames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.gif");
        let red = [255u8, 0, 0].repeat(4 * 3);
        let blue = [0u8, 0, 255].repeat(4 * 3);
        write_gif(&path, &[red, blue.clone(), blue], 4, 3, 100).unwrap();
        let mut dec = gif::DecodeOptions::new();
        dec.set_color_output(gif::ColorOutput::RGBA);
        let mut d = dec.read_info(File::open(&path).unwrap()).unwrap();
        let mut n = 0;
        let mut first = Vec::new();
        while let Some(f) = d.read_next_frame().unwrap() {
            if n == 0 {
                first = f.buffer.to_vec();
            }
            assert_eq!(f.delay, 10);
            n += 1;
        }
        assert_eq!(n, 3);
        assert_eq!(&first[..4], &[255, 0, 0, 255]);
    }

    #[test]
    fn wrong_frame_size_names_the_frame() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("b.gif");
        let err = write_gif(&path, &[vec![0; 36], vec![0; 5]], 4, 3, 100).unwrap_err();
        assert!(err.to_string().contains("frame 1"), "{err}");
    }
}
