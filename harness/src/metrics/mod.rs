//! Agreement between a predictor's policy scores and the ground truth.
//!
//! Definitions follow `peers.md` §3 (SimplerEnv, scipy): Pearson r, Spearman ρ
//! (Pearson on average ranks), Kendall τ_b (tie-corrected), rank inversions,
//! MMRV exactly as SimplerEnv defines it (predicted first, actual second), and
//! regret@1. Undefined correlations (a constant vector, fewer than 2 policies)
//! are `None`, never a silent 0.

pub mod bootstrap;
pub mod ceiling;

use serde::Serialize;

/// Pearson correlation, `None` when undefined (n < 2 or a constant vector).
///
/// ```
/// // scipy.stats.pearsonr([1, 2, 3, 4, 5], [10, 9, 2.5, 6, 4]) = -0.7426106572325057
/// let r = harness::metrics::pearson(&[1., 2., 3., 4., 5.], &[10., 9., 2.5, 6., 4.]).unwrap();
/// assert!((r + 0.7426106572325057).abs() < 1e-12);
/// ```
pub fn pearson(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 2 || y.len() != n || x.iter().chain(y).any(|v| !v.is_finite()) {
        return None;
    }
    let (mx, my) = (x.iter().sum::<f64>() / n as f64, y.iter().sum::<f64>() / n as f64);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y) {
        sxy += (a - mx) * (b - my);
        sxx += (a - mx).powi(2);
        syy += (b - my).powi(2);
    }
    let denom = (sxx * syy).sqrt();
    if sxy.is_finite() && denom.is_finite() && denom > 0.0 {
        return Some((sxy / denom).clamp(-1.0, 1.0));
    }
    // A sum overflowed or underflowed (at 92f9f2b, values near ±1e300 made every
    // square infinite and r came out as -0.0; values near 1e-200 gave none): centre
    // and scale by the largest deviation, then sum again. Ordinary inputs never get
    // here, so their r keeps its rounding.
    let centred = |v: &[f64]| -> Option<Vec<f64>> {
        let mean = v.iter().map(|a| a / n as f64).sum::<f64>();
        let d: Vec<f64> = v.iter().map(|a| a - mean).collect();
        let scale = d.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        (scale > 0.0 && scale.is_finite()).then(|| d.iter().map(|a| a / scale).collect())
    };
    let (dx, dy) = (centred(x)?, centred(y)?);
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in dx.iter().zip(&dy) {
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    if sxx == 0.0 || syy == 0.0 {
        return None;
    }
    Some((sxy / (sxx * syy).sqrt()).clamp(-1.0, 1.0))
}

/// Average ranks (1-based; tied values share the mean of their ranks).
pub fn average_ranks(x: &[f64]) -> Vec<f64> {
    let mut order: Vec<usize> = (0..x.len()).collect();
    order.sort_by(|&a, &b| x[a].total_cmp(&x[b]));
    let mut ranks = vec![0.0; x.len()];
    let mut i = 0;
    while i < order.len() {
        let mut j = i;
        while j + 1 < order.len() && x[order[j + 1]] == x[order[i]] {
            j += 1;
        }
        let r = (i + j) as f64 / 2.0 + 1.0;
        for &k in &order[i..=j] {
            ranks[k] = r;
        }
        i = j + 1;
    }
    ranks
}

/// Spearman's ρ: Pearson on average ranks.
pub fn spearman(x: &[f64], y: &[f64]) -> Option<f64> {
    pearson(&average_ranks(x), &average_ranks(y))
}

/// Kendall's τ_b = (n_c − n_d) / sqrt((n₀ − n₁)(n₀ − n₂)).
pub fn kendall_tau_b(x: &[f64], y: &[f64]) -> Option<f64> {
    let n = x.len();
    if n < 2 || y.len() != n {
        return None;
    }
    let (mut nc, mut nd, mut tx, mut ty) = (0f64, 0f64, 0f64, 0f64);
    for i in 0..n {
        for j in i + 1..n {
            let (dx, dy) = (x[i] - x[j], y[i] - y[j]);
            if dx == 0.0 {
                tx += 1.0;
            }
            if dy == 0.0 {
                ty += 1.0;
            }
            if dx * dy > 0.0 {
                nc += 1.0;
            } else if dx * dy < 0.0 {
                nd += 1.0;
            }
        }
    }
    let n0 = (n * (n - 1) / 2) as f64;
    let denom = ((n0 - tx) * (n0 - ty)).sqrt();
    (denom > 0.0).then(|| (nc - nd) / denom)
}

/// Pairs ordered differently by prediction and ground truth.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Inversions {
    /// `#{i < j : (p_i − p_j)(a_i − a_j) < 0}`.
    pub count: usize,
    /// `count / (N (N − 1) / 2)`.
    pub fraction: f64,
    /// Pairs `(i, j)` tied in the prediction or in the ground truth (not inversions).
    pub ties: Vec<(usize, usize)>,
}

/// Counts rank inversions between `pred` and `actual`.
pub fn rank_inversions(pred: &[f64], actual: &[f64]) -> Inversions {
    let n = pred.len().min(actual.len());
    let (mut count, mut ties) = (0, Vec::new());
    for i in 0..n {
        for j in i + 1..n {
            let (dp, da) = (pred[i] - pred[j], actual[i] - actual[j]);
            if dp * da < 0.0 {
                count += 1;
            } else if dp == 0.0 || da == 0.0 {
                ties.push((i, j));
            }
        }
    }
    let pairs = n * n.saturating_sub(1) / 2;
    Inversions { count, fraction: if pairs > 0 { count as f64 / pairs as f64 } else { 0.0 }, ties }
}

/// Mean maximum rank violation (SimplerEnv): `RV_i = max_j |a_i − a_j| · 1[(p_i > p_j) ≠ (a_i > a_j)]`,
/// `MMRV = mean_i RV_i`. Asymmetric: `pred` first, `actual` second; the magnitude uses the ground truth.
pub fn mmrv(pred: &[f64], actual: &[f64]) -> f64 {
    let n = pred.len().min(actual.len());
    if n == 0 {
        return 0.0;
    }
    let total: f64 = (0..n)
        .map(|i| {
            (0..n)
                .filter(|&j| (pred[i] > pred[j]) != (actual[i] > actual[j]))
                .map(|j| (actual[i] - actual[j]).abs())
                .fold(0.0, f64::max)
        })
        .sum();
    total / n as f64
}

/// Regret of picking the predictor's best policy: `max a − a[argmax p]` (ties in `p`
/// resolved to the first index).
pub fn regret_at_1(pred: &[f64], actual: &[f64]) -> f64 {
    let n = pred.len().min(actual.len());
    if n == 0 {
        return 0.0;
    }
    let best_pred = (0..n).fold(0, |b, i| if pred[i] > pred[b] { i } else { b });
    actual[..n].iter().copied().fold(f64::NEG_INFINITY, f64::max) - actual[best_pred]
}

/// Mean absolute difference of paired scores (0 for none).
pub fn mean_abs_error(pred: &[f64], actual: &[f64]) -> f64 {
    let n = pred.len().min(actual.len());
    if n == 0 {
        return 0.0;
    }
    pred.iter().zip(actual).map(|(p, a)| (p - a).abs()).sum::<f64>() / n as f64
}

/// All agreement metrics of one set of policy scores.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Agreement {
    /// Pearson r (None if undefined).
    pub pearson: Option<f64>,
    /// Spearman ρ.
    pub spearman: Option<f64>,
    /// Kendall τ_b.
    pub kendall_tau_b: Option<f64>,
    /// Rank inversions.
    pub rank_inversions: Inversions,
    /// MMRV (lower is better).
    pub mmrv: f64,
    /// Regret@1 (lower is better).
    pub regret_at_1: f64,
    /// Mean over policies of |predicted − actual| (lower is better): how well the
    /// world model predicts each policy's absolute score, not just its order.
    pub mean_abs_error: f64,
}

/// Computes every agreement metric; `pred` and `actual` are per-policy scores.
pub fn agreement(pred: &[f64], actual: &[f64]) -> Agreement {
    Agreement {
        pearson: pearson(pred, actual),
        spearman: spearman(pred, actual),
        kendall_tau_b: kendall_tau_b(pred, actual),
        rank_inversions: rank_inversions(pred, actual),
        mmrv: mmrv(pred, actual),
        regret_at_1: regret_at_1(pred, actual),
        mean_abs_error: mean_abs_error(pred, actual),
    }
}

#[cfg(test)]
mod tests;
