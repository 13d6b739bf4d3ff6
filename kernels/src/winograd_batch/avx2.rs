//! The AVX2 transforms of [`super`]: each channel's images are turned
//! image-innermost with 8x8 register transposes (and back, for the output), and
//! every run of 8 images' tile is transformed in registers. The portable versions
//! go through arrays that the compiler keeps on the stack, and copy element by
//! element; these were half the U-Net's convolution time. Called only after
//! [`crate::elementwise::has_avx2_fma`] has confirmed AVX2 and FMA.

use std::arch::x86_64::{
    __m256, _mm256_add_ps, _mm256_loadu_ps, _mm256_permute2f128_ps, _mm256_setzero_ps, _mm256_shuffle_ps,
    _mm256_storeu_ps, _mm256_sub_ps, _mm256_unpackhi_ps, _mm256_unpacklo_ps,
};

use super::{Geometry, LANES};

/// The transpose of an 8x8 block: row `k` of the result is column `k` of `r`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn transpose8(r: [__m256; 8]) -> [__m256; 8] {
    let t = [
        _mm256_unpacklo_ps(r[0], r[1]),
        _mm256_unpackhi_ps(r[0], r[1]),
        _mm256_unpacklo_ps(r[2], r[3]),
        _mm256_unpackhi_ps(r[2], r[3]),
        _mm256_unpacklo_ps(r[4], r[5]),
        _mm256_unpackhi_ps(r[4], r[5]),
        _mm256_unpacklo_ps(r[6], r[7]),
        _mm256_unpackhi_ps(r[6], r[7]),
    ];
    // s[0] = [r00 r10 r20 r30 | r04 r14 r24 r34], s[1] the columns 1 | 5, ...
    let s = [
        _mm256_shuffle_ps::<0x44>(t[0], t[2]),
        _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
        _mm256_shuffle_ps::<0x44>(t[1], t[3]),
        _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
        _mm256_shuffle_ps::<0x44>(t[4], t[6]),
        _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
        _mm256_shuffle_ps::<0x44>(t[5], t[7]),
        _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
    ];
    [
        _mm256_permute2f128_ps::<0x20>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x20>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x20>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x20>(s[3], s[7]),
        _mm256_permute2f128_ps::<0x31>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x31>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x31>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x31>(s[3], s[7]),
    ]
}

/// Visits `n` images × `hw` pixels: `block(dst, j0, p0)` for every whole 8 × 8 block,
/// then `elem(dst, j, p)` for the pixels and images left over. The partition
/// [`to_lanes`] and [`add_from_lanes`] share.
#[inline(always)]
fn by_blocks(
    n: usize,
    hw: usize,
    dst: &mut [f32],
    mut block: impl FnMut(&mut [f32], usize, usize),
    mut elem: impl FnMut(&mut [f32], usize, usize),
) {
    let (full_j, full_p) = (n / LANES * LANES, hw / LANES * LANES);
    for j0 in (0..full_j).step_by(LANES) {
        for p0 in (0..full_p).step_by(LANES) {
            block(dst, j0, p0);
        }
        for p in full_p..hw {
            for j in j0..j0 + LANES {
                elem(dst, j, p);
            }
        }
    }
    for j in full_j..n {
        for p in 0..hw {
            elem(dst, j, p);
        }
    }
}

/// `n` planes of `hw` pixels (`planes`, `[n, hw]`) into `buf` `[hw, l]` (image innermost):
/// 8x8 blocks by transposes, the rest element by element. Called once per channel; kept
/// out of line so that the tile loop it precedes stays compact.
#[inline(never)]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn to_lanes(planes: &[f32], n: usize, hw: usize, l: usize, buf: &mut [f32]) {
    assert!(planes.len() >= n * hw && buf.len() >= hw * l && n <= l);
    by_blocks(
        n,
        hw,
        buf,
        |buf, j0, p0| {
            // SAFETY: j0 + 8 <= n and p0 + 8 <= hw, so each row read lies in `planes`
            // (asserted above); each column written, (p0 + k) · l + j0 + 8 <= hw · l, in `buf`.
            unsafe {
                let rows = std::array::from_fn(|r| _mm256_loadu_ps(planes.as_ptr().add((j0 + r) * hw + p0)));
                for (k, col) in transpose8(rows).iter().enumerate() {
                    _mm256_storeu_ps(buf.as_mut_ptr().add((p0 + k) * l + j0), *col);
                }
            }
        },
        |buf, j, p| buf[p * l + j] = planes[j * hw + p],
    );
}

/// Adds `buf` `[hw, l]` (image innermost) to `n` planes `[n, hw]`: the inverse of [`to_lanes`].
#[inline(never)]
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
fn add_from_lanes(buf: &[f32], n: usize, hw: usize, l: usize, planes: &mut [f32]) {
    assert!(planes.len() >= n * hw && buf.len() >= hw * l && n <= l);
    by_blocks(
        n,
        hw,
        planes,
        |planes, j0, p0| {
            // SAFETY: as in `to_lanes`, with the roles of the two buffers swapped.
            unsafe {
                let cols = std::array::from_fn(|k| _mm256_loadu_ps(buf.as_ptr().add((p0 + k) * l + j0)));
                for (r, row) in transpose8(cols).iter().enumerate() {
                    let d = planes.as_mut_ptr().add((j0 + r) * hw + p0);
                    _mm256_storeu_ps(d, _mm256_add_ps(_mm256_loadu_ps(d), *row));
                }
            }
        },
        |planes, j, p| planes[j * hw + p] += buf[p * l + j],
    );
}

/// `Bᵀ` along one axis: `[d0 − d2, d1 + d2, d2 − d1, d1 − d3]`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn bt([d0, d1, d2, d3]: [__m256; 4]) -> [__m256; 4] {
    [_mm256_sub_ps(d0, d2), _mm256_add_ps(d1, d2), _mm256_sub_ps(d2, d1), _mm256_sub_ps(d1, d3)]
}

/// `Aᵀ` along one axis: `[m0 + m1 + m2, m1 − m2 − m3]`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn at([m0, m1, m2, m3]: [__m256; 4]) -> [__m256; 2] {
    [_mm256_add_ps(_mm256_add_ps(m0, m1), m2), _mm256_sub_ps(_mm256_sub_ps(m1, m2), m3)]
}

/// Pixel `(y, x)` of images `j0 .. j0 + 8` from `buf` (`[h·w, lanes]`); zeros outside
/// the image (`y` or `x` past the edge, or wrapped below zero).
#[inline(always)]
#[allow(unsafe_code)]
fn lanes_at(buf: &[f32], g: &Geometry, y: usize, x: usize, j0: usize) -> __m256 {
    if y < g.h && x < g.w {
        let run = &buf[(y * g.w + x) * g.lanes + j0..][..LANES];
        // SAFETY: `run` holds 8 floats.
        unsafe { _mm256_loadu_ps(run.as_ptr()) }
    } else {
        // SAFETY: no memory is touched; the callers run only where AVX is available.
        unsafe { _mm256_setzero_ps() }
    }
}

/// [`super::transform_input`]: per channel, the chunk's images image-innermost in
/// `buf` (`[h·w, lanes]`, no border: taps outside the image read zero), then each
/// tile's `Bᵀ d B` for 8 images at a time into `v` (`[16, c, tiles]`).
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn transform_input_avx2(x: &[f32], c: usize, g: &Geometry, buf: &mut [f32], v: &mut [f32]) {
    let (h, w, l) = (g.h, g.w, g.lanes);
    let (hw, th, tw) = (h * w, h / 2, w / 2);
    let tiles = th * tw * l;
    assert!(v.len() >= 16 * c * tiles && buf.len() >= hw * l && l.is_multiple_of(LANES));
    let buf = &mut buf[..hw * l];
    // Padding lanes (images n .. l) stay zero.
    buf.fill(0.0);
    for ci in 0..c {
        to_lanes(&x[(ci * g.imgs + g.i0) * hw..], g.n, hw, l, buf);
        for ty in 0..th {
            for tx in 0..tw {
                for j0 in (0..l).step_by(LANES) {
                    // Input pixel (2ty + r − 1, 2tx + q − 1) of images j0 .. j0 + 8.
                    let px = |r: usize, q: usize| {
                        lanes_at(buf, g, (2 * ty + r).wrapping_sub(1), (2 * tx + q).wrapping_sub(1), j0)
                    };
                    let rows: [[__m256; 4]; 4] =
                        std::array::from_fn(|r| bt([px(r, 0), px(r, 1), px(r, 2), px(r, 3)]));
                    let base = ci * tiles + (ty * tw + tx) * l + j0;
                    let cols: [[__m256; 4]; 4] =
                        std::array::from_fn(|j| bt([rows[0][j], rows[1][j], rows[2][j], rows[3][j]]));
                    for (j, col) in cols.iter().enumerate() {
                        for (i, val) in col.iter().enumerate() {
                            // SAFETY: point i·4 + j < 16, so the run ends within `v` (asserted above).
                            unsafe {
                                _mm256_storeu_ps(v.as_mut_ptr().add((i * 4 + j) * c * tiles + base), *val)
                            };
                        }
                    }
                }
            }
        }
    }
}

/// [`super::transform_output`]: per output channel, each tile's `Aᵀ m A` for 8 images
/// at a time into `buf` (`[h·w, lanes]`), then added to the chunk's images in `out`.
#[target_feature(enable = "avx2,fma")]
#[allow(unsafe_code)]
pub(super) fn transform_output_avx2(m: &[f32], c: usize, g: &Geometry, buf: &mut [f32], out: &mut [f32]) {
    let (h, w, l) = (g.h, g.w, g.lanes);
    let (hw, th, tw) = (h * w, h / 2, w / 2);
    let tiles = th * tw * l;
    assert!(m.len() >= 16 * c * tiles && buf.len() >= hw * l && l.is_multiple_of(LANES));
    let buf = &mut buf[..hw * l];
    for co in 0..c {
        for ty in 0..th {
            for tx in 0..tw {
                for j0 in (0..l).step_by(LANES) {
                    let base = co * tiles + (ty * tw + tx) * l + j0;
                    // SAFETY: point p < 16, so the run ends within `m` (asserted above).
                    let mv = |p: usize| unsafe { _mm256_loadu_ps(m.as_ptr().add(p * c * tiles + base)) };
                    let cols: [[__m256; 2]; 4] =
                        std::array::from_fn(|j| at([mv(j), mv(4 + j), mv(8 + j), mv(12 + j)]));
                    let rows: [[__m256; 2]; 2] =
                        std::array::from_fn(|dy| at([cols[0][dy], cols[1][dy], cols[2][dy], cols[3][dy]]));
                    for (dy, [even, odd]) in rows.into_iter().enumerate() {
                        let e = ((2 * ty + dy) * w + 2 * tx) * l + j0;
                        // SAFETY: pixel (2ty + dy, 2tx + 1) is inside the image, so both runs
                        // end within `buf` (hw · l floats).
                        unsafe {
                            _mm256_storeu_ps(buf.as_mut_ptr().add(e), even);
                            _mm256_storeu_ps(buf.as_mut_ptr().add(e + l), odd);
                        }
                    }
                }
            }
        }
        add_from_lanes(buf, g.n, hw, l, &mut out[(co * g.imgs + g.i0) * hw..]);
    }
}
