//! A zero-bordered feature map: the input format of the direct and Winograd 3x3
//! convolutions ([`crate::direct_conv`], [`crate::winograd`]), with the fills
//! (copy, 2x upsampling, GroupNorm + SiLU) that produce it.

use crate::elementwise::{Norm, exp, mean_var};

/// Output pixels per tile of the direct convolution (two 8-lane AVX registers); rows
/// are padded to whole tiles.
pub(crate) const LANES: usize = 16;

/// A feature map `[c, h, w]` stored with a one-pixel zero border and rows padded
/// to whole tiles, so a 3x3 tap never needs a bounds branch.
#[derive(Clone, Debug)]
pub struct Padded {
    c: usize,
    h: usize,
    w: usize,
    /// Floats per stored row (`w` rounded up to a whole tile, plus the border).
    stride: usize,
    data: Vec<f32>,
}

impl Padded {
    /// A zero map of `c` channels, `h` x `w` pixels.
    #[inline]
    pub fn zeros(c: usize, h: usize, w: usize) -> Self {
        let stride = w.div_ceil(LANES) * LANES + 2;
        Self { c, h, w, stride, data: crate::elementwise::zeros(c * (h + 2) * stride) }
    }

    /// Floats per stored row (the interior rounded up to whole tiles, plus the border).
    #[inline(always)]
    pub(crate) fn stride(&self) -> usize {
        self.stride
    }

    /// The stored values: per channel `h + 2` rows of [`Padded::stride`] floats.
    #[inline(always)]
    pub(crate) fn data(&self) -> &[f32] {
        &self.data
    }

    /// Channels.
    #[inline]
    pub fn channels(&self) -> usize {
        self.c
    }

    /// Interior height.
    #[inline]
    pub fn height(&self) -> usize {
        self.h
    }

    /// Interior width.
    #[inline]
    pub fn width(&self) -> usize {
        self.w
    }

    /// Bordered row `by` (0 is the zero row above the interior) of channel `ch`: the
    /// left border, the `w` interior values, then zeros to the stored row's end
    /// (at least `w + 2` values).
    #[inline]
    pub fn bordered_row(&self, ch: usize, by: usize) -> &[f32] {
        &self.data[(ch * (self.h + 2) + by) * self.stride..][..self.stride]
    }

    /// The interior row `y` of channel `ch` (`w` values).
    #[inline]
    fn row_mut(&mut self, ch: usize, y: usize) -> &mut [f32] {
        let start = (ch * (self.h + 2) + y + 1) * self.stride + 1;
        &mut self.data[start..start + self.w]
    }

    /// The interior (`[c, h, w]`, without the border), in order.
    pub fn interior(&self) -> impl Iterator<Item = f32> + '_ {
        (0..self.c).flat_map(move |ch| {
            (0..self.h).flat_map(move |y| {
                let start = (ch * (self.h + 2) + y + 1) * self.stride + 1;
                self.data[start..start + self.w].iter().copied()
            })
        })
    }

    /// Copies `src` (`[c, h, w]`, or `[c, h/2, w/2]` repeated 2x2 when `upsample`) inside the border.
    pub fn fill(&mut self, src: &[f32], upsample: bool) {
        let (c, h, w) = (self.c, self.h, self.w);
        let (sh, sw) = if upsample { (h / 2, w / 2) } else { (h, w) };
        assert_eq!(src.len(), c * sh * sw);
        for ch in 0..c {
            for y in 0..h {
                let sy = if upsample { y / 2 } else { y };
                let s = &src[(ch * sh + sy) * sw..][..sw];
                let row = self.row_mut(ch, y);
                if upsample {
                    for (x, v) in row.iter_mut().enumerate() {
                        *v = s[x / 2];
                    }
                } else {
                    row.copy_from_slice(s);
                }
            }
        }
    }

    /// `silu(groupnorm(src))` (`[c, h, w]`) inside the border: statistics per
    /// group of `c / groups` channels, biased variance, then the affine per channel.
    pub fn fill_norm_silu(&mut self, src: &[f32], norm: &Norm) {
        #[cfg(target_arch = "x86_64")]
        if crate::elementwise::has_avx2_fma() {
            // SAFETY: the CPU supports AVX2 and FMA (checked just above), the
            // requirement of calling a function compiled with those features.
            #[allow(unsafe_code)]
            unsafe {
                self.fill_norm_silu_avx2(src, norm)
            };
            return;
        }
        self.fill_norm_silu_impl(src, norm);
    }

    /// [`Padded::fill_norm_silu`] compiled for AVX2 + FMA (its loops vectorise 8 wide).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn fill_norm_silu_avx2(&mut self, src: &[f32], norm: &Norm) {
        self.fill_norm_silu_impl(src, norm);
    }

    /// The statistics by [`mean_var`], then one pass for the output.
    #[inline(always)]
    fn fill_norm_silu_impl(&mut self, src: &[f32], norm: &Norm) {
        let (c, h, w) = (self.c, self.h, self.w);
        let plane = h * w;
        let per = c / norm.groups;
        let n = (per * plane) as f64;
        for g in 0..norm.groups {
            let part = &src[g * per * plane..(g + 1) * per * plane];
            let (mean, var) = mean_var(|| std::iter::once(part), n);
            let inv = 1.0 / (var + norm.eps).sqrt();
            for ch in g * per..(g + 1) * per {
                let scale = (inv * f64::from(norm.gamma[ch])) as f32;
                let shift = (f64::from(norm.beta[ch]) - mean * inv * f64::from(norm.gamma[ch])) as f32;
                for y in 0..h {
                    let s = &src[(ch * h + y) * w..][..w];
                    for (d, &v) in self.row_mut(ch, y).iter_mut().zip(s) {
                        let t = v * scale + shift;
                        *d = t / (1.0 + exp(-t));
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upsampling_repeats_each_pixel_two_by_two() {
        // A 1-channel 1x2 map [1, 2] becomes the 2x4 map [1 1 2 2; 1 1 2 2].
        let mut p = Padded::zeros(1, 2, 4);
        p.fill(&[1.0, 2.0], true);
        assert_eq!(p.row_mut(0, 0), &[1.0, 1.0, 2.0, 2.0]);
        assert_eq!(p.row_mut(0, 1), &[1.0, 1.0, 2.0, 2.0]);
        // The border stays zero: the row above the first is all zeros.
        assert!(p.data[..p.stride].iter().all(|&v| v == 0.0));
    }

    #[test]
    fn norm_silu_normalises_each_group() {
        // Two channels, one group, values 0 and 2: mean 1, variance 1, so the normalised
        // values are -1 and +1 (eps 0); silu(-1) = -1/(1+e) = -0.26894, silu(1) = 0.73106.
        let norm = Norm { groups: 1, gamma: vec![1.0, 1.0], beta: vec![0.0, 0.0], eps: 0.0 };
        let mut p = Padded::zeros(2, 1, 1);
        p.fill_norm_silu(&[0.0, 2.0], &norm);
        assert!((p.row_mut(0, 0)[0] + 0.26894).abs() < 1e-5);
        assert!((p.row_mut(1, 0)[0] - 0.73106).abs() < 1e-5);
        // With γ = 2 and β = 1 on channel 1: silu(2·1 + 1) = 3/(1+e^-3) = 2.85772.
        let norm = Norm { gamma: vec![1.0, 2.0], beta: vec![0.0, 1.0], ..norm };
        p.fill_norm_silu(&[0.0, 2.0], &norm);
        assert!((p.row_mut(1, 0)[0] - 2.85772).abs() < 1e-4);
    }
}
