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

/// PyTorch's antialiased bilinear taps (`F.interpolate(mode="bilinear", align_corners=False,
/// antialias=True)`, what torchvision's `Resize` does to float tensors) of `dst` outputs from
/// `src` inputs: per output, the first source index and the normalised weights from it on.
///
/// The filter is the triangle `1 − |x|` stretched by the reduction `s = src / dst` when `s > 1`
/// (so a reduction averages over `s` inputs instead of reading two), centred at `s·(i + ½)`; its
/// taps are the inputs `j` in `[⌊c − support + ½⌋, ⌊c + support + ½⌋)` (support `s`, or 1 when
/// enlarging), weighted `tri((j − c + ½)/max(s, 1))` and divided by their sum, in single
/// precision as PyTorch's CPU kernel computes them for float images.
pub fn torch_aa_taps(src: usize, dst: usize) -> Vec<(usize, Vec<f32>)> {
    let scale = src as f32 / dst as f32;
    let (support, invscale) = if scale >= 1.0 { (scale, 1.0 / scale) } else { (1.0, 1.0) };
    let max_taps = (support.ceil() as usize) * 2 + 1;
    (0..dst)
        .map(|i| {
            let centre = scale * (i as f32 + 0.5);
            let lo = ((centre - support + 0.5) as i64).max(0) as usize;
            let hi = ((centre + support + 0.5) as i64).min(src as i64).max(lo as i64) as usize;
            let n = (hi - lo).min(max_taps);
            let mut w: Vec<f32> = (0..n)
                .map(|j| {
                    let x = ((j + lo) as f32 - centre + 0.5) * invscale;
                    (1.0 - x.abs()).max(0.0)
                })
                .collect();
            let total: f32 = w.iter().sum();
            if total != 0.0 {
                w.iter_mut().for_each(|v| *v /= total);
            }
            (lo, w)
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

    /// The pattern resized with [`torch_aa_taps`], width first then height, as PyTorch's
    /// separable CPU kernel does.
    fn aa_resize(src: usize, dst: usize) -> Vec<f32> {
        let img: Vec<f32> = pattern(src).into_iter().map(f32::from).collect();
        let taps = torch_aa_taps(src, dst);
        let mut rows = vec![0.0f32; src * dst * 3]; // [src rows, dst cols, 3]
        for y in 0..src {
            for (x, (lo, w)) in taps.iter().enumerate() {
                for c in 0..3 {
                    rows[(y * dst + x) * 3 + c] =
                        w.iter().enumerate().map(|(j, w)| w * img[(y * src + lo + j) * 3 + c]).sum();
                }
            }
        }
        let mut out = vec![0.0f32; dst * dst * 3];
        for (y, (lo, w)) in taps.iter().enumerate() {
            for x in 0..dst {
                for c in 0..3 {
                    out[(y * dst + x) * 3 + c] =
                        w.iter().enumerate().map(|(j, w)| w * rows[((lo + j) * dst + x) * 3 + c]).sum();
                }
            }
        }
        out
    }

    fn read_f32(name: &str) -> Vec<f32> {
        let path = format!("{}/tests/fixtures/{name}", env!("CARGO_MANIFEST_DIR"));
        let bytes = std::fs::read(&path).unwrap_or_default();
        bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
    }

    #[test]
    fn antialiased_resizing_is_pytorchs() {
        // torch_aa_*.f32: scripts/fixtures/torch_resize.py (torch 2.15.0), the pattern as floats
        // through F.interpolate(bilinear, align_corners=False, antialias=True). Values are in
        // [0, 255]; f32 sums of up to 5 taps agree to about 1e-4 whatever the order.
        for (src, dst) in [(96, 72), (84, 96)] {
            let want = read_f32(&format!("torch_aa_{src}_to_{dst}.f32"));
            let got = aa_resize(src, dst);
            assert_eq!(got.len(), want.len(), "{src} -> {dst}");
            let max = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(max < 2e-3, "{src} -> {dst}: max |diff| {max}");
        }
        // A reduction by 4/3 reads the inputs in a window of 2 · 4/3 around each output's
        // centre: 2 or 3 of them, some of them 3 (plain bilinear always reads 2); enlarging
        // reads at most two with weight, as plain bilinear does.
        let lens: Vec<usize> = torch_aa_taps(96, 72).iter().map(|(_, w)| w.len()).collect();
        assert!(lens.iter().all(|n| (2..=3).contains(n)) && lens.contains(&3), "{lens:?}");
        assert!(torch_aa_taps(84, 96).iter().all(|(_, w)| w.iter().filter(|&&v| v > 0.0).count() <= 2));
        // Enlarging with antialiasing is plain bilinear: the same weights as torch_taps.
        for ((lo, w), (i0, i1, l1)) in torch_aa_taps(84, 96).into_iter().zip(torch_taps(84, 96)) {
            let mut dense = vec![0.0f32; 84];
            w.iter().enumerate().for_each(|(j, v)| dense[lo + j] += v);
            let mut plain = vec![0.0f32; 84];
            plain[i0] += 1.0 - l1;
            plain[i1] += l1;
            assert!(dense.iter().zip(&plain).all(|(a, b)| (a - b).abs() < 1e-6), "{lo} {w:?} {i0} {i1} {l1}");
        }
    }
}
