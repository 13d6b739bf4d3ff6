//! The algebra of Winograd's F(2x2, 3x3) (Lavin & Gray 2016), shared by the
//! per-image kernels ([`super`]) and the batch kernels
//! ([`crate::winograd_batch`]): the filter transform `G g Gᵀ`, the input
//! transform `Bᵀ d B` and the output transform `Aᵀ m A`, on runs of `L` tiles at a
//! time so that the loops vectorise.

/// Filter transform `G` (4x3).
const G: [[f64; 3]; 4] = [[1.0, 0.0, 0.0], [0.5, 0.5, 0.5], [0.5, -0.5, 0.5], [0.0, 0.0, 1.0]];

/// `G g Gᵀ` of one 3x3 filter `g` (`[ky, kx]`), as `[i · 4 + j]`, computed in f64.
pub fn transform_filter(g: &[f32]) -> [f32; 16] {
    std::array::from_fn(|p| {
        let (gi, gj) = (&G[p / 4], &G[p % 4]);
        let mut s = 0.0;
        for (ky, &a) in gi.iter().enumerate() {
            for (kx, &b) in gj.iter().enumerate() {
                s += a * f64::from(g[ky * 3 + kx]) * b;
            }
        }
        s as f32
    })
}

/// `Bᵀ` along one axis for runs of `L` tiles: the four input rows (or columns) of each
/// tile, `d0 .. d3`, become `[d0 − d2, d1 + d2, d2 − d1, d1 − d3]`.
#[inline(always)]
fn input_1d<const L: usize>([d0, d1, d2, d3]: [&[f32; L]; 4]) -> [[f32; L]; 4] {
    [
        std::array::from_fn(|k| d0[k] - d2[k]),
        std::array::from_fn(|k| d1[k] + d2[k]),
        std::array::from_fn(|k| d2[k] - d1[k]),
        std::array::from_fn(|k| d1[k] - d3[k]),
    ]
}

/// `Aᵀ` along one axis for runs of `L` tiles: `[m0 + m1 + m2, m1 − m2 − m3]`.
#[inline(always)]
fn output_1d<const L: usize>([m0, m1, m2, m3]: [&[f32; L]; 4]) -> [[f32; L]; 2] {
    [std::array::from_fn(|k| m0[k] + m1[k] + m2[k]), std::array::from_fn(|k| m1[k] - m2[k] - m3[k])]
}

/// `Bᵀ d B` for runs of `L` tiles: `d[r][q]` (tile input row r, column q) to `v[i][j]`.
#[inline(always)]
pub fn input_2d<const L: usize>(d: &[[[f32; L]; 4]; 4]) -> [[[f32; L]; 4]; 4] {
    let t: [[[f32; L]; 4]; 4] = std::array::from_fn(|r| input_1d([&d[r][0], &d[r][1], &d[r][2], &d[r][3]]));
    let cols: [[[f32; L]; 4]; 4] =
        std::array::from_fn(|j| input_1d([&t[0][j], &t[1][j], &t[2][j], &t[3][j]]));
    std::array::from_fn(|i| std::array::from_fn(|j| cols[j][i]))
}

/// `Aᵀ m A` for runs of `L` tiles: `m[i · 4 + j]` to the 2x2 outputs `y[dy][dx]`.
#[inline(always)]
pub fn output_2d<const L: usize>(m: &[[f32; L]; 16]) -> [[[f32; L]; 2]; 2] {
    let cols: [[[f32; L]; 2]; 4] =
        std::array::from_fn(|j| output_1d([&m[j], &m[4 + j], &m[8 + j], &m[12 + j]]));
    std::array::from_fn(|dy| output_1d([&cols[0][dy], &cols[1][dy], &cols[2][dy], &cols[3][dy]]))
}
