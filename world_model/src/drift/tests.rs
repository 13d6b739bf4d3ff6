//! Tests of the drifting loss: a hand-computed case, an independent scalar
//! reference implementation, the single-positive reduction, scale invariance and
//! the zero field at the positive.

use burn::tensor::{Device, Tensor, TensorData};

use super::*;

fn device() -> Device {
    Device::flex()
}

fn t3(v: Vec<f32>, shape: [usize; 3]) -> Tensor<3> {
    Tensor::from_data(TensorData::new(v, shape), &device())
}

fn to_vec(t: Tensor<3>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec::<f32>().unwrap()
}

/// A plain f64 transcription of spec §2 for one element (loops, no tensors).
// Index loops mirror the formulas (d_ij, A_ij) on purpose.
#[allow(clippy::needless_range_loop)]
fn reference(x: &[Vec<f64>], neg: &[(Vec<f64>, f64)], pos: &[Vec<f64>], temps: &[f64]) -> Vec<Vec<f64>> {
    let (g, s) = (x.len(), x[0].len());
    let mut y: Vec<Vec<f64>> = x.to_vec();
    let mut w = vec![1.0; g];
    for (v, wv) in neg {
        y.push(v.clone());
        w.push(*wv);
    }
    let split = y.len();
    for v in pos {
        y.push(v.clone());
        w.push(1.0);
    }
    let m = y.len();
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
    let mut d = vec![vec![0.0; m]; g];
    for i in 0..g {
        for j in 0..m {
            d[i][j] = (dot(&x[i], &x[i]) + dot(&y[j], &y[j]) - 2.0 * dot(&x[i], &y[j])).max(1e-8).sqrt();
        }
    }
    let wsum: f64 = w.iter().sum();
    let scale: f64 =
        (0..g).map(|i| (0..m).map(|j| w[j] * d[i][j]).sum::<f64>()).sum::<f64>() / (g as f64 * wsum);
    let sigma = (scale / (s as f64).sqrt()).max(1e-3);
    let mut dh: Vec<Vec<f64>> = d.iter().map(|r| r.iter().map(|v| v / scale.max(1e-3)).collect()).collect();
    for i in 0..g {
        dh[i][i] = 1e6;
    }
    let mut v = vec![vec![0.0; s]; g];
    for &r in temps {
        let l: Vec<Vec<f64>> = dh.iter().map(|row| row.iter().map(|v| -v / r).collect()).collect();
        let prow: Vec<Vec<f64>> = l
            .iter()
            .map(|row| {
                let mx = row.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let z: f64 = row.iter().map(|v| (v - mx).exp()).sum();
                row.iter().map(|v| (v - mx).exp() / z).collect()
            })
            .collect();
        let mut pcol = vec![vec![0.0; m]; g];
        for j in 0..m {
            let mx = (0..g).map(|i| l[i][j]).fold(f64::NEG_INFINITY, f64::max);
            let z: f64 = (0..g).map(|i| (l[i][j] - mx).exp()).sum();
            for i in 0..g {
                pcol[i][j] = (l[i][j] - mx).exp() / z;
            }
        }
        let a: Vec<Vec<f64>> = (0..g)
            .map(|i| (0..m).map(|j| (prow[i][j] * pcol[i][j]).max(1e-6).sqrt() * w[j]).collect())
            .collect();
        let mut vr = vec![vec![0.0; s]; g];
        for i in 0..g {
            let sp: f64 = (split..m).map(|j| a[i][j]).sum();
            let sn: f64 = (0..split).map(|j| a[i][j]).sum();
            for k in 0..s {
                let attract: f64 = (split..m).map(|j| a[i][j] * y[j][k] / sigma).sum();
                let repel: f64 = (0..split).map(|j| a[i][j] * y[j][k] / sigma).sum();
                vr[i][k] = sn * attract - sp * repel;
            }
        }
        let ms = vr.iter().flatten().map(|v| v * v).sum::<f64>() / (g * s) as f64;
        let lambda = ms.max(1e-8).sqrt();
        for i in 0..g {
            for k in 0..s {
                v[i][k] += vr[i][k] / lambda;
            }
        }
    }
    v
}

#[test]
fn single_sample_hand_computed() {
    // s = 1, one generated sample x = 0, one positive y⁺ = 1, no negatives: the columns
    // are [self, positive] with weights [1, 1].
    // d = [sqrt(1e-8), 1] = [1e-4, 1]; scale = (1e-4 + 1) / (1 · 2) = 0.50005 = σ (s = 1).
    // d̂ = [1e6 (self masked), 1 / 0.50005]; for any R the row softmax is [0, 1] and the
    // column softmax (one row) is [1, 1], so A = [sqrt(max(0, 1e-6)), 1] = [1e-3, 1].
    // V_R = S⁻ A⁺ ỹ⁺ − S⁺ A_self x̃ = 1e-3 · 1 · (1/σ) − 1 · 1e-3 · 0 = 1e-3 / 0.50005
    //     = 0.00199980, so loss_R = V_R² = 3.99920e-6, and the normalised field is +1.
    // Loss = mean(V²) = 1; ∂L/∂x = −2 V / (b g s σ) = −2 / 0.50005 = −3.99960.
    let dev = device().autodiff();
    let x = Tensor::<3>::from_data(TensorData::new(vec![0.0f32], [1, 1, 1]), &dev).require_grad();
    let pos = Tensor::<3>::from_data(TensorData::new(vec![1.0f32], [1, 1, 1]), &dev);
    let (loss, field) = drift_loss(x.clone(), None, &pos, &[0.05]);
    assert!((to_vec(field.sigma.clone())[0] - 0.50005).abs() < 1e-6);
    assert!((field.loss_r[0] - 3.9992e-6).abs() < 1e-9, "{:?}", field.loss_r);
    assert!((to_vec(field.v.clone())[0] - 1.0).abs() < 1e-5);
    let l = loss.clone().into_data().convert::<f32>().try_into_vec::<f32>().unwrap()[0];
    assert!((l - 1.0).abs() < 1e-5, "{l}");
    let grads = loss.backward();
    let gx = x.grad(&grads).unwrap().into_data().convert::<f32>().try_into_vec::<f32>().unwrap();
    assert!((gx[0] + 3.9996).abs() < 1e-3, "{gx:?}");
    // Three temperatures, each a unit-RMS field in the same direction: V = 3.
    let (_, field) = drift_loss(x, None, &pos, &PUSHT_TEMPERATURES);
    assert!((to_vec(field.v)[0] - 3.0).abs() < 1e-4);
}

#[test]
fn symmetric_pair_around_the_positive_has_zero_field() {
    // x = (0, 2), y⁺ = 1, R = 0.05: each sample's self entry is masked and its partner is
    // 2 scaled units away against 1 for the positive, so both get the floor affinity
    // 1e-3 while the positive gets sqrt(1 · 0.5). The floor-weighted negatives average
    // (1e-3 · 0 + 1e-3 · 2) / 2e-3 = 1 is exactly the positive: V = 0 (no spurious drift).
    let x = t3(vec![0.0, 2.0], [1, 2, 1]);
    let pos = t3(vec![1.0], [1, 1, 1]);
    let f = drift_field(&x, None, &pos, &[0.05]);
    assert!(f.loss_r[0] < 1e-12, "{:?}", f.loss_r);
}

/// Deterministic pseudo-random numbers in [-1, 1) for test inputs.
fn lcg(seed: u64, n: usize) -> Vec<f64> {
    let mut z = seed;
    (0..n)
        .map(|_| {
            z = z.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((z >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        })
        .collect()
}

#[test]
fn matches_the_scalar_reference_with_negatives_and_positives() {
    let (b, g, n, p, s) = (2, 5, 2, 2, 7);
    let xs = lcg(1, b * g * s);
    let ns = lcg(2, b * n * s);
    let ps = lcg(3, b * p * s);
    let ws = [0.5f64, 3.0, 1.5, 2.0]; // b x n
    let f32s = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let x = t3(f32s(&xs), [b, g, s]);
    let neg = Negatives {
        y: t3(f32s(&ns), [b, n, s]),
        w: Tensor::from_data(TensorData::new(f32s(&ws), [b, n]), &device()),
    };
    let pos = t3(f32s(&ps), [b, p, s]);
    let got = to_vec(drift_field(&x, Some(&neg), &pos, &PUSHT_TEMPERATURES).v);
    for e in 0..b {
        let rows = |v: &[f64], k: usize| {
            (0..k).map(|i| v[(e * k + i) * s..(e * k + i + 1) * s].to_vec()).collect::<Vec<_>>()
        };
        let negs: Vec<(Vec<f64>, f64)> =
            rows(&ns, n).into_iter().zip(ws[e * n..(e + 1) * n].iter().copied()).collect();
        let want = reference(&rows(&xs, g), &negs, &rows(&ps, p), &[0.02, 0.05, 0.2]);
        for i in 0..g {
            for k in 0..s {
                let gv = got[(e * g + i) * s + k] as f64;
                assert!(
                    (gv - want[i][k]).abs() < 2e-3 * (1.0 + want[i][k].abs()),
                    "b{e} i{i} k{k}: {gv} vs {}",
                    want[i][k]
                );
            }
        }
    }
}

#[test]
fn single_positive_field_points_from_the_cloud_to_the_positive() {
    // A cloud of generated samples around the origin and one positive far along +1:
    // every sample's field has a positive component towards the positive.
    let (g, s) = (8, 16);
    let xs: Vec<f32> = lcg(9, g * s).iter().map(|&v| 0.3 * v as f32).collect();
    let target: Vec<f32> = vec![2.0; s];
    let x = t3(xs.clone(), [1, g, s]);
    let pos = t3(target.clone(), [1, 1, s]);
    let v = to_vec(drift_field(&x, None, &pos, &PUSHT_TEMPERATURES).v);
    for i in 0..g {
        let dot: f32 = (0..s).map(|k| v[i * s + k] * (target[k] - xs[i * s + k])).sum();
        assert!(dot > 0.0, "sample {i}: field points away from the positive ({dot})");
    }
}

#[test]
fn field_is_invariant_to_the_scale_of_the_features() {
    let (g, s) = (6, 5);
    let xs: Vec<f32> = lcg(4, g * s).iter().map(|&v| v as f32).collect();
    let ps: Vec<f32> = lcg(5, s).iter().map(|&v| v as f32).collect();
    let field = |k: f32| {
        let x = t3(xs.iter().map(|v| v * k).collect(), [1, g, s]);
        let pos = t3(ps.iter().map(|v| v * k).collect(), [1, 1, s]);
        to_vec(drift_field(&x, None, &pos, &PUSHT_TEMPERATURES).v)
    };
    let (a, b) = (field(1.0), field(37.0));
    for (p, q) in a.iter().zip(&b) {
        assert!((p - q).abs() < 1e-3 * (1.0 + p.abs()), "{p} vs {q}");
    }
}

#[test]
fn samples_at_the_positive_feel_no_field() {
    // Generated samples that coincide with the positive: every difference ỹ⁺ − ỹ_j is
    // zero, so the raw field (loss_R = mean V_R²) vanishes up to f32 rounding. (The
    // returned V is V_R / max(RMS, 1e-4), so rounding noise is not reduced there.)
    let (g, s) = (4, 3);
    let p = vec![0.5f32, -1.0, 2.0];
    let at = t3(p.iter().cycle().take(g * s).copied().collect(), [1, g, s]);
    let pos = t3(p.clone(), [1, 1, s]);
    let still = drift_field(&at, None, &pos, &PUSHT_TEMPERATURES).loss_r;
    let moved = t3(
        p.iter().cycle().take(g * s).enumerate().map(|(i, v)| v + 0.1 * (i % 5) as f32).collect(),
        [1, g, s],
    );
    let pulled = drift_field(&moved, None, &pos, &PUSHT_TEMPERATURES).loss_r;
    for (a, b) in still.iter().zip(&pulled) {
        assert!(*a < 1e-6 * b, "at the positive {a}, displaced {b}");
    }
}

#[test]
fn problem_weights_scale_each_problem_s_loss() {
    // Two problems of 3 samples in 2 dims, one positive each.
    let x = t3(vec![0.1, 0.2, -0.3, 0.4, 0.5, -0.6, 1.0, 0.0, 0.2, 0.9, -0.4, 0.3], [2, 3, 2]);
    let pos = t3(vec![0.0, 0.0, 1.0, 1.0], [2, 1, 2]);
    let temps = [0.02, 0.05, 0.2];
    let loss = |w: Option<Vec<f32>>| {
        let w = w.map(|v| Tensor::<1>::from_floats(v.as_slice(), &device()));
        drift_loss_weighted(x.clone(), None, &pos, &temps, w).0.into_scalar::<f32>()
    };
    // Each problem's own loss, from single-problem calls.
    let single = |i: usize| {
        let xi = x.clone().narrow(0, i, 1);
        drift_loss(xi, None, &pos.clone().narrow(0, i, 1), &temps).0.into_scalar::<f32>()
    };
    let (l0, l1) = (single(0), single(1));
    // Unit weights are the plain mean; weights (3, 1) give (3·l0 + l1) / 2.
    assert!((loss(Some(vec![1.0, 1.0])) - loss(None)).abs() < 1e-6);
    assert!((loss(None) - (l0 + l1) / 2.0).abs() < 1e-5);
    assert!((loss(Some(vec![3.0, 1.0])) - (3.0 * l0 + l1) / 2.0).abs() < 1e-5);
}

/// The 2-D setting of the accentuation tests: two generated samples at (0, ±0.05), the
/// positive at (1, 0) and the "current frame" o_t at (0, −1), weighted `w`.
fn accentuated_field(w: Option<f32>) -> Vec<f32> {
    let x = t3(vec![0.0, 0.05, 0.0, -0.05], [1, 2, 2]);
    let pos = t3(vec![1.0, 0.0], [1, 1, 2]);
    let neg =
        w.map(|w| Negatives { y: t3(vec![0.0, -1.0], [1, 1, 2]), w: Tensor::from_floats([[w]], &device()) });
    to_vec(drift_field(&x, neg.as_ref(), &pos, &PUSHT_TEMPERATURES).v)
}

#[test]
fn accentuation_at_alpha_one_changes_nothing() {
    // α = 1 gives the current frame weight (α − 1)(N − 1) = 0: it adds nothing to the
    // scale (Σ w d) nor to any affinity (A_ij ∝ w_j), so the field is the plain one.
    let (plain, zero) = (accentuated_field(None), accentuated_field(Some(0.0)));
    for (p, q) in plain.iter().zip(&zero) {
        assert!((p - q).abs() < 1e-5, "{plain:?} vs {zero:?}");
    }
}

#[test]
fn accentuation_pushes_samples_away_from_the_current_frame() {
    // Without o_t the two samples' y-components cancel by symmetry (each is pushed from
    // the other, the positive lies on y = 0). With o_t below them at weight
    // (α − 1)(N − 1) = 3 (α = 4, N = 2) the pair as a whole moves up, away from it
    // (the sample nearer o_t still feels its neighbour more: affinities fall off as
    // exp(−d̂/R) with small R, so the weight shifts the balance without reversing it).
    let plain = accentuated_field(None);
    assert!((plain[1] + plain[3]).abs() < 1e-4, "{plain:?}");
    let v = accentuated_field(Some(3.0));
    assert!(v[1] + v[3] > 0.1, "{v:?}");
    // Both still move towards the positive in x.
    assert!(v[0] > 0.0 && v[2] > 0.0, "{v:?}");
}
