//! PNG images and filmstrips (rows of equally sized frames).

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

/// Errors while writing a PNG, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("{path}: {message}")]
pub struct PngError {
    /// The file.
    pub path: PathBuf,
    /// What failed.
    pub message: String,
}

/// An RGB image.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    /// Row-major RGB bytes.
    pub pixels: Vec<u8>,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

/// Lays out rows of `w x h` RGB frames on a white canvas with a 2-pixel gap.
pub fn filmstrip(rows: &[Vec<Vec<u8>>], w: usize, h: usize) -> Image {
    let gap = 2;
    let cols = rows.iter().map(Vec::len).max().unwrap_or(0);
    let width = (cols * (w + gap)).saturating_sub(gap).max(1);
    let height = (rows.len() * (h + gap)).saturating_sub(gap).max(1);
    let mut pixels = vec![255u8; width * height * 3];
    for (r, row) in rows.iter().enumerate() {
        for (c, frame) in row.iter().enumerate() {
            if frame.len() != w * h * 3 {
                continue;
            }
            for y in 0..h {
                let dst = ((r * (h + gap) + y) * width + c * (w + gap)) * 3;
                pixels[dst..dst + w * 3].copy_from_slice(&frame[y * w * 3..(y + 1) * w * 3]);
            }
        }
    }
    Image { pixels, width, height }
}

/// Writes RGB bytes as a PNG.
///
/// # Errors
/// [`PngError`] naming the file.
pub fn write_png(path: &Path, rgb: &[u8], width: usize, height: usize) -> Result<(), PngError> {
    let err = |e: &dyn std::fmt::Display| PngError { path: path.to_path_buf(), message: e.to_string() };
    let file = File::create(path).map_err(|e| err(&e))?;
    let (w, h) = (u32::try_from(width).map_err(|e| err(&e))?, u32::try_from(height).map_err(|e| err(&e))?);
    let mut enc = png::Encoder::new(BufWriter::new(file), w, h);
    enc.set_color(png::ColorType::Rgb);
    enc.set_depth(png::BitDepth::Eight);
    let mut writer = enc.write_header().map_err(|e| err(&e))?;
    writer.write_image_data(rgb).map_err(|e| err(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filmstrip_places_frames_with_gaps() {
        let red = [255u8, 0, 0].repeat(2 * 2);
        let blue = [0u8, 0, 255].repeat(2 * 2);
        let img = filmstrip(&[vec![red.clone(), blue.clone()], vec![blue]], 2, 2);
        // 2 columns x (2 px + 2 gap) - 2 = 6 wide; 2 rows -> 6 high.
        assert_eq!((img.width, img.height), (6, 6));
        assert_eq!(&img.pixels[0..3], &[255, 0, 0]); // row 0, frame 0
        assert_eq!(&img.pixels[4 * 3..5 * 3], &[0, 0, 255]); // row 0, frame 1 at x = 4
        assert_eq!(&img.pixels[(4 * 6) * 3..(4 * 6) * 3 + 3], &[0, 0, 255]); // row 1 at y = 4
        assert_eq!(&img.pixels[2 * 3..3 * 3], &[255, 255, 255]); // the gap
    }

    #[test]
    fn png_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.png");
        write_png(&p, &[1, 2, 3, 4, 5, 6], 2, 1).unwrap();
        let dec = png::Decoder::new(std::io::BufReader::new(File::open(&p).unwrap()));
        let mut r = dec.read_info().unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        r.next_frame(&mut buf).unwrap();
        assert_eq!(&buf[..6], &[1, 2, 3, 4, 5, 6]);
    }
}
