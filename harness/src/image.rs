//! Image-quality metrics on 8-bit RGB frames, computed the way the DriftWorld
//! authors report them (scikit-image on uint8 with `data_range = 255`):
//!
//! - [`psnr`]: `10 log10(255² / MSE)`;
//! - [`ssim`]: scikit-image's `structural_similarity(..., channel_axis=-1,
//!   data_range=255)` defaults — a 7x7 uniform window, K1 = 0.01, K2 = 0.03, sample
//!   covariances (×49/48), the mean of the SSIM map after cropping 3 pixels from
//!   every border, averaged over channels.

/// PSNR (dB) of two byte images of the same length; infinite when identical.
pub fn psnr(a: &[u8], b: &[u8]) -> f64 {
    let mse = a.iter().zip(b).map(|(x, y)| (f64::from(*x) - f64::from(*y)).powi(2)).sum::<f64>()
        / a.len().max(1) as f64;
    if mse == 0.0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() }
}

/// Mean SSIM of two `h x w x c` (HWC) byte images; `None` if an image is smaller
/// than the 7x7 window or the sizes disagree.
pub fn ssim(a: &[u8], b: &[u8], h: usize, w: usize, c: usize) -> Option<f64> {
    const WIN: usize = 7;
    if h < WIN || w < WIN || a.len() != h * w * c || b.len() != a.len() {
        return None;
    }
    let (c1, c2) = ((0.01f64 * 255.0).powi(2), (0.03f64 * 255.0).powi(2));
    let np = (WIN * WIN) as f64;
    let cov_norm = np / (np - 1.0);
    let pad = WIN / 2;
    let mut total = 0.0;
    for ch in 0..c {
        let px = |img: &[u8], y: usize, x: usize| f64::from(img[(y * w + x) * c + ch]);
        let mut sum = 0.0;
        let mut count = 0usize;
        for y in pad..h - pad {
            for x in pad..w - pad {
                let (mut sx, mut sy, mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for yy in y - pad..=y + pad {
                    for xx in x - pad..=x + pad {
                        let (u, v) = (px(a, yy, xx), px(b, yy, xx));
                        sx += u;
                        sy += v;
                        sxx += u * u;
                        syy += v * v;
                        sxy += u * v;
                    }
                }
                let (ux, uy) = (sx / np, sy / np);
                let vx = cov_norm * (sxx / np - ux * ux);
                let vy = cov_norm * (syy / np - uy * uy);
                let vxy = cov_norm * (sxy / np - ux * uy);
                let s =
                    ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
                sum += s;
                count += 1;
            }
        }
        total += sum / count as f64;
    }
    Some(total / c as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(h: usize, w: usize, f: impl Fn(usize, usize, usize) -> usize) -> Vec<u8> {
        let mut v = Vec::with_capacity(h * w * 3);
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    v.push((f(y, x, c) % 256) as u8);
                }
            }
        }
        v
    }

    #[test]
    fn ssim_matches_scikit_image() {
        // Reference from scikit-image 0.25 (numpy 2):
        //   a = (7x + 13y + 50c) % 256, b = (5x + 11y + 30c + (xy % 17)) % 256, shape (12, 10, 3);
        //   structural_similarity(a, b, channel_axis=2, data_range=255) = 0.7441491792487528.
        let a = pattern(12, 10, |y, x, c| x * 7 + y * 13 + c * 50);
        let b = pattern(12, 10, |y, x, c| x * 5 + y * 11 + c * 30 + (x * y) % 17);
        let s = ssim(&a, &b, 12, 10, 3).unwrap();
        assert!((s - 0.744_149_179_248_752_8).abs() < 1e-12, "{s}");
        assert_eq!(ssim(&a, &a, 12, 10, 3), Some(1.0));
        assert_eq!(ssim(&a[..18], &b[..18], 2, 3, 3), None);
    }

    #[test]
    fn psnr_reference_values() {
        // One pixel off by 255 out of 4 values: mse = 255²/4, PSNR = 10 log10(4) = 6.0206 dB.
        assert!((psnr(&[0, 0, 0, 0], &[255, 0, 0, 0]) - 6.0206).abs() < 1e-4);
        assert_eq!(psnr(&[7, 8], &[7, 8]), f64::INFINITY);
    }
}
