//! The small dense linear algebra the operational-space controller needs:
//! row-major `N × M` arrays, products, a symmetric positive-definite inverse and
//! NumPy's pseudo-inverse (`np.linalg.pinv`: singular values below 1e-15 × the
//! largest are dropped) for symmetric matrices, by Jacobi rotations.
//!
//! Sizes are fixed and tiny (3, 6 and 7), so plain index loops are enough.

#![allow(clippy::needless_range_loop)]

/// A row-major `R × C` matrix.
pub type Mat<const R: usize, const C: usize> = [[f64; C]; R];

/// `a · b`.
pub fn mul<const R: usize, const K: usize, const C: usize>(a: &Mat<R, K>, b: &Mat<K, C>) -> Mat<R, C> {
    let mut out = [[0.0; C]; R];
    for (i, row) in out.iter_mut().enumerate() {
        for k in 0..K {
            let aik = a[i][k];
            for (j, v) in row.iter_mut().enumerate() {
                *v += aik * b[k][j];
            }
        }
    }
    out
}

/// `aᵀ`.
pub fn transpose<const R: usize, const C: usize>(a: &Mat<R, C>) -> Mat<C, R> {
    let mut out = [[0.0; R]; C];
    for (i, row) in a.iter().enumerate() {
        for (j, v) in row.iter().enumerate() {
            out[j][i] = *v;
        }
    }
    out
}

/// `a · x`.
pub fn mul_vec<const R: usize, const C: usize>(a: &Mat<R, C>, x: &[f64; C]) -> [f64; R] {
    let mut out = [0.0; R];
    for (o, row) in out.iter_mut().zip(a) {
        *o = row.iter().zip(x).map(|(p, q)| p * q).sum();
    }
    out
}

/// The identity.
pub fn identity<const N: usize>() -> Mat<N, N> {
    let mut out = [[0.0; N]; N];
    for (i, row) in out.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    out
}

/// The inverse of a symmetric positive-definite matrix (Cholesky), or `None`
/// when it is not positive definite.
pub fn spd_inverse<const N: usize>(a: &Mat<N, N>) -> Option<Mat<N, N>> {
    // a = L Lᵀ.
    let mut l = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..=i {
            let s: f64 = (0..j).map(|k| l[i][k] * l[j][k]).sum();
            if i == j {
                let d = a[i][i] - s;
                if d <= 0.0 || !d.is_finite() {
                    return None;
                }
                l[i][j] = d.sqrt();
            } else {
                l[i][j] = (a[i][j] - s) / l[j][j];
            }
        }
    }
    // Solve L Lᵀ x = e_c for every column c.
    let mut inv = [[0.0; N]; N];
    for c in 0..N {
        let mut y = [0.0; N];
        for i in 0..N {
            let rhs = if i == c { 1.0 } else { 0.0 };
            y[i] = (rhs - (0..i).map(|k| l[i][k] * y[k]).sum::<f64>()) / l[i][i];
        }
        for i in (0..N).rev() {
            let x = (y[i] - (i + 1..N).map(|k| l[k][i] * inv[k][c]).sum::<f64>()) / l[i][i];
            inv[i][c] = x;
        }
    }
    Some(inv)
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations:
/// `a = V diag(w) Vᵀ`, the eigenvectors in V's columns.
fn sym_eigen<const N: usize>(a: &Mat<N, N>) -> ([f64; N], Mat<N, N>) {
    let mut m = *a;
    let mut v = identity::<N>();
    for _sweep in 0..64 {
        let off: f64 = (0..N)
            .flat_map(|i| (0..N).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i][j] * m[i][j])
            .sum();
        let scale: f64 = (0..N).map(|i| m[i][i] * m[i][i]).sum::<f64>().max(f64::MIN_POSITIVE);
        if off <= 1e-30 * scale {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if m[p][q] == 0.0 {
                    continue;
                }
                let theta = (m[q][q] - m[p][p]) / (2.0 * m[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let (mkp, mkq) = (m[k][p], m[k][q]);
                    m[k][p] = c * mkp - s * mkq;
                    m[k][q] = s * mkp + c * mkq;
                }
                for k in 0..N {
                    let (mpk, mqk) = (m[p][k], m[q][k]);
                    m[p][k] = c * mpk - s * mqk;
                    m[q][k] = s * mpk + c * mqk;
                }
                for row in v.iter_mut() {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let mut w = [0.0; N];
    for (i, wi) in w.iter_mut().enumerate() {
        *wi = m[i][i];
    }
    (w, v)
}

/// NumPy's `pinv` of a symmetric matrix: eigenvalues whose magnitude is below
/// 1e-15 × the largest are treated as zero.
pub fn sym_pinv<const N: usize>(a: &Mat<N, N>) -> Mat<N, N> {
    let (w, v) = sym_eigen(a);
    let largest = w.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
    let cutoff = 1e-15 * largest;
    let mut out = [[0.0; N]; N];
    for (k, &wk) in w.iter().enumerate() {
        if wk.abs() <= cutoff {
            continue;
        }
        let inv = 1.0 / wk;
        for i in 0..N {
            for j in 0..N {
                out[i][j] += v[i][k] * inv * v[j][k];
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverses_of_a_known_matrix() {
        // a = [[4, 2], [2, 3]]: det = 4·3 − 2·2 = 8, so a⁻¹ = [[3, −2], [−2, 4]] / 8.
        let a = [[4.0, 2.0], [2.0, 3.0]];
        let want = [[0.375, -0.25], [-0.25, 0.5]];
        for inv in [spd_inverse(&a).unwrap(), sym_pinv(&a)] {
            for i in 0..2 {
                for j in 0..2 {
                    assert!((inv[i][j] - want[i][j]).abs() < 1e-12, "{inv:?}");
                }
            }
        }
        assert!(spd_inverse(&[[1.0, 2.0], [2.0, 1.0]]).is_none(), "indefinite");
    }

    #[test]
    fn pinv_of_a_singular_matrix_inverts_its_range_only() {
        // a = u uᵀ with u = (1, 1)/√2 · √2 = (1, 1): eigenvalues 2 and 0, so
        // pinv(a) = u uᵀ / |u|⁴ = [[1, 1], [1, 1]] / 4.
        let p = sym_pinv(&[[1.0, 1.0], [1.0, 1.0]]);
        for row in p {
            for v in row {
                assert!((v - 0.25).abs() < 1e-12, "{p:?}");
            }
        }
    }

    #[test]
    fn products() {
        let a = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]];
        // a aᵀ = [[1+4+9, 4+10+18], [.., 16+25+36]] = [[14, 32], [32, 77]].
        assert_eq!(mul(&a, &transpose(&a)), [[14.0, 32.0], [32.0, 77.0]]);
        assert_eq!(mul_vec(&a, &[1.0, 0.0, -1.0]), [-2.0, -2.0]);
    }
}
