//! OpenCV's `cv2.resize(img, (w, h))` with its default INTER_LINEAR on 8-bit images: what a
//! renderer needs to reproduce another codebase's frames. GPC's Push-T draws at 512² and resizes
//! to 96² this way (no prefilter: a 5.33× reduction reads 2 × 2 source pixels per output pixel).
//! Reductions match OpenCV 5.0.0 bit for bit (512² → 96², a random image and a pattern);
//! enlargements do not yet: 84² → 96² differs in 74 of 27,648 bytes, by 1 level each.
//!
//! The arithmetic is OpenCV's fixed point for 8-bit data: for output position d, the source
//! coordinate is `(d + 0.5)·scale − 0.5`, split into `floor` and fraction `f` (clamped to the
//! first and last pixel), with weights `round(2048·(1 − f))` and `round(2048·f)`; the
//! horizontal pass sums two weighted pixels, the vertical pass combines two rows as its SIMD
//! kernel does, `((h0 >> 4)·b0 >> 16) + ((h1 >> 4)·b1 >> 16)`, then `(· + 2) >> 2`.

/// Source index and weights (scaled by 2048) for each of `dst` outputs from `src` inputs,
/// computed in `f32` as OpenCV does.
fn taps(src: usize, dst: usize) -> Vec<(usize, usize, [i32; 2])> {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|d| {
            let fx = ((d as f64 + 0.5) * scale - 0.5) as f32;
            let mut sx = fx.floor() as i64;
            let mut f = fx - sx as f32;
            if sx < 0 {
                f = 0.0;
                sx = 0;
            }
            if sx >= src as i64 - 1 {
                f = 0.0;
                sx = src as i64 - 1;
            }
            let w = |v: f32| (v * 2048.0).round() as i32;
            let s = sx as usize;
            (s, (s + 1).min(src - 1), [w(1.0 - f), w(f)])
        })
        .collect()
}

/// Resizes an `h × w × c` row-major 8-bit image to `oh × ow × c` as `cv2.resize` with
/// INTER_LINEAR does. Returns `None` when `img` is not `h·w·c` bytes or a side is 0.
pub fn resize_linear_u8(img: &[u8], h: usize, w: usize, c: usize, oh: usize, ow: usize) -> Option<Vec<u8>> {
    if img.len() != h * w * c || [h, w, c, oh, ow].contains(&0) {
        return None;
    }
    let (tx, ty) = (taps(w, ow), taps(h, oh));
    let mut out = vec![0u8; oh * ow * c];
    for (dy, &(y0, y1, [b0, b1])) in ty.iter().enumerate() {
        for (dx, &(x0, x1, [a0, a1])) in tx.iter().enumerate() {
            for ch in 0..c {
                let p = |y: usize, x: usize| i32::from(img[(y * w + x) * c + ch]);
                let h0 = p(y0, x0) * a0 + p(y0, x1) * a1;
                let h1 = p(y1, x0) * a0 + p(y1, x1) * a1;
                let v = ((((h0 >> 4) * b0) >> 16) + (((h1 >> 4) * b1) >> 16) + 2) >> 2;
                out[(dy * ow + dx) * c + ch] = v.clamp(0, 255) as u8;
            }
        }
    }
    Some(out)
}

/// PyTorch's bilinear taps (`align_corners=False`, no antialiasing) of `dst` outputs from `src`
/// inputs: per output, the two source indices and the weight of the second, in single precision.
pub fn torch_taps(src: usize, dst: usize) -> Vec<(usize, usize, f32)> {
    let scale = src as f32 / dst as f32;
    (0..dst)
        .map(|x| {
            let s = ((x as f32 + 0.5) * scale - 0.5).max(0.0);
            let i0 = (s as usize).min(src - 1);
            let i1 = (i0 + 1).min(src - 1);
            (i0, i1, s - i0 as f32)
        })
        .collect()
}

/// Resizes an `h × w × c` 8-bit image to `oh × ow × c` as PyTorch's
/// `F.interpolate(mode="bilinear", align_corners=False)` does on its float values, then
/// `round()` (half to even) and clamp to bytes: how DriftWorld's robomimic data brought 84²
/// frames to 96². Source coordinate `(x + 0.5)·w/ow − 0.5`, clamped below at 0, in single
/// precision. Returns `None` when `img` is not `h·w·c` bytes or a side is 0.
pub fn resize_bilinear_torch_u8(
    img: &[u8],
    h: usize,
    w: usize,
    c: usize,
    oh: usize,
    ow: usize,
) -> Option<Vec<u8>> {
    if img.len() != h * w * c || [h, w, c, oh, ow].contains(&0) {
        return None;
    }
    let (tx, ty) = (torch_taps(w, ow), torch_taps(h, oh));
    let mut out = vec![0u8; oh * ow * c];
    for (dy, &(y0, y1, ly)) in ty.iter().enumerate() {
        for (dx, &(x0, x1, lx)) in tx.iter().enumerate() {
            for ch in 0..c {
                let p = |y: usize, x: usize| f32::from(img[(y * w + x) * c + ch]);
                let v = (1.0 - ly) * ((1.0 - lx) * p(y0, x0) + lx * p(y0, x1))
                    + ly * ((1.0 - lx) * p(y1, x0) + lx * p(y1, x1));
                out[(dy * ow + dx) * c + ch] = v.round_ties_even().clamp(0.0, 255.0) as u8;
            }
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fixtures' pattern: (7x + 13y + 29c + (x·y mod 17)) mod 256.
    fn pattern(side: usize) -> Vec<u8> {
        let mut v = Vec::with_capacity(side * side * 3);
        for y in 0..side {
            for x in 0..side {
                for c in 0..3 {
                    v.push(((7 * x + 13 * y + 29 * c + (x * y) % 17) % 256) as u8);
                }
            }
        }
        v
    }

    /// Bytes of `resize_linear_u8(pattern(src))` that differ from OpenCV's, and by how much at most.
    fn against_opencv(src: usize, dst: usize, want: &[u8]) -> (usize, u8) {
        let got = resize_linear_u8(&pattern(src), src, src, 3, dst, dst).unwrap_or_default();
        assert_eq!(got.len(), want.len());
        let off = got.iter().zip(want).filter(|(a, b)| a != b).count();
        (off, got.iter().zip(want).map(|(a, b)| a.abs_diff(*b)).max().unwrap_or(0))
    }

    #[test]
    fn a_reduction_matches_opencv_bit_for_bit() {
        // scripts/fixtures/cv2_resize.py: cv2.resize of the pattern by OpenCV 5.0.0.
        let want = include_bytes!("../tests/fixtures/cv2_resize_512_to_96.bin");
        assert_eq!(against_opencv(512, 96, want), (0, 0));
    }

    #[test]
    fn an_enlargement_is_within_one_level_of_opencv() {
        // Not yet exact: 74 of 27,648 bytes are 1 level off (OpenCV 5.0.0, 84² → 96²).
        let want = include_bytes!("../tests/fixtures/cv2_resize_84_to_96.bin");
        let (off, max) = against_opencv(84, 96, want);
        assert!(max <= 1 && off <= 100, "{off} bytes differ, by up to {max}");
    }

    #[test]
    fn a_wrong_size_is_refused_and_a_flat_image_stays_flat() {
        assert_eq!(resize_linear_u8(&[0; 11], 2, 2, 3, 1, 1), None);
        // Weights sum to 2048 in each pass, so a constant survives: 200 → 200.
        assert_eq!(resize_linear_u8(&[200; 5 * 7 * 3], 5, 7, 3, 3, 4), Some(vec![200; 3 * 4 * 3]));
    }

    #[test]
    fn pytorchs_bilinear_upsampling_of_84_to_96_is_reproduced() {
        // torch_bilinear_84_to_96.bin: scripts/fixtures/torch_resize.py (torch 2.5.1), the
        // same pattern image upsampled with F.interpolate(bilinear, align_corners=False),
        // rounded to bytes.
        let want =
            std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/torch_bilinear_84_to_96.bin"))
                .unwrap_or_default();
        let got = resize_bilinear_torch_u8(&pattern(84), 84, 84, 3, 96, 96).unwrap_or_default();
        assert_eq!(got.len(), want.len());
        let differ: Vec<usize> =
            got.iter().zip(&want).enumerate().filter(|(_, (a, b))| a != b).map(|(i, _)| i).collect();
        assert!(
            differ.is_empty(),
            "{} of {} bytes differ, first at {:?}",
            differ.len(),
            want.len(),
            differ.first()
        );
        assert_eq!(resize_bilinear_torch_u8(&[0; 5], 2, 2, 3, 4, 4), None);
    }
}
