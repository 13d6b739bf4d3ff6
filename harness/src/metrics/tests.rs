//! Metric values checked against published (scipy documentation) and hand-computed values.

use super::*;

#[test]
fn spearman_matches_scipy_docs() {
    // scipy.stats.spearmanr([1, 2, 3, 4, 5], [5, 6, 7, 8, 7]).statistic = 0.8207826816681233
    let r = spearman(&[1., 2., 3., 4., 5.], &[5., 6., 7., 8., 7.]).unwrap();
    assert!((r - 0.8207826816681233).abs() < 1e-12, "{r}");
}

#[test]
fn kendall_tau_b_matches_scipy_docs() {
    // scipy.stats.kendalltau([12, 2, 1, 12, 2], [1, 4, 7, 1, 0]).statistic = -0.47140452079103173
    let t = kendall_tau_b(&[12., 2., 1., 12., 2.], &[1., 4., 7., 1., 0.]).unwrap();
    assert!((t + 0.47140452079103173).abs() < 1e-12, "{t}");
}

#[test]
fn average_ranks_share_ties() {
    // [10, 20, 10, 30] -> 10s take ranks 1 and 2 -> 1.5 each; 20 -> 3; 30 -> 4.
    assert_eq!(average_ranks(&[10., 20., 10., 30.]), vec![1.5, 3.0, 1.5, 4.0]);
}

#[test]
fn undefined_correlations_are_none() {
    assert_eq!(pearson(&[1., 1., 1.], &[1., 2., 3.]), None);
    assert_eq!(pearson(&[1.], &[1.]), None);
    assert_eq!(kendall_tau_b(&[2., 2.], &[1., 3.]), None);
    assert_eq!(pearson(&[1., 2., 3.], &[2., 4., 6.]), Some(1.0));
}

#[test]
fn inversions_hand_computed() {
    // pred [0.9, 0.5, 0.7, 0.5], actual [0.8, 0.6, 0.4, 0.2]:
    // (0,1) +,+ ok; (0,2) +,+ ok; (0,3) +,+ ok; (1,2) -,+ inversion; (1,3) tie in pred;
    // (2,3) +,+ ok. One inversion of 6 pairs, one tie (1,3).
    let inv = rank_inversions(&[0.9, 0.5, 0.7, 0.5], &[0.8, 0.6, 0.4, 0.2]);
    assert_eq!(inv.count, 1);
    assert!((inv.fraction - 1.0 / 6.0).abs() < 1e-12);
    assert_eq!(inv.ties, vec![(1, 3)]);
    assert_eq!(rank_inversions(&[1., 2., 3.], &[4., 5., 6.]).count, 0);
}

#[test]
fn mmrv_hand_computed_and_asymmetric() {
    // pred [0.2, 0.5, 0.4], actual [0.1, 0.3, 0.6].
    // i=0: vs 1: (0.2>0.5)=F, (0.1>0.3)=F ok; vs 2: F,F ok -> RV_0 = 0.
    // i=1: vs 0: T,T ok; vs 2: (0.5>0.4)=T, (0.3>0.6)=F violation |0.3-0.6| = 0.3 -> RV_1 = 0.3.
    // i=2: vs 0: T,T ok; vs 1: (0.4>0.5)=F, (0.6>0.3)=T violation 0.3 -> RV_2 = 0.3.
    // MMRV = 0.6 / 3 = 0.2.
    let (p, a) = ([0.2, 0.5, 0.4], [0.1, 0.3, 0.6]);
    assert!((mmrv(&p, &a) - 0.2).abs() < 1e-12);
    // Swapping the arguments changes the magnitudes used: actual' = [0.2, 0.5, 0.4],
    // violations are the same pairs (1,2), magnitude |0.5-0.4| = 0.1 -> 0.2 / 3.
    assert!((mmrv(&a, &p) - 0.2 / 3.0).abs() < 1e-12);
    // A predicted tie with a real difference is a violation charged to the better one:
    // pred [0.5, 0.5], actual [0.9, 0.1]: i=0: (F) != (T) -> 0.8; i=1: F == F -> 0. MMRV 0.4.
    assert!((mmrv(&[0.5, 0.5], &[0.9, 0.1]) - 0.4).abs() < 1e-12);
}

#[test]
fn mean_abs_error_hand_computed() {
    // |0.1 - 0.8| + |0.9 - 0.6| + |0.5 - 0.7| = 0.7 + 0.3 + 0.2 = 1.2, over 3 policies: 0.4.
    assert!((mean_abs_error(&[0.1, 0.9, 0.5], &[0.8, 0.6, 0.7]) - 0.4).abs() < 1e-12);
    assert_eq!(mean_abs_error(&[], &[]), 0.0);
    // One policy has an error even though it has no ranking: |0.3 - 0.5| = 0.2.
    let j = agreement(&[0.3], &[0.5]).to_json(&["a"], None);
    assert!((j["mean_abs_error"].as_f64().unwrap() - 0.2).abs() < 1e-12, "{j}");
}

#[test]
fn regret_hand_computed() {
    // The predictor picks policy 1 (0.9); its true score 0.6 is 0.2 below the best 0.8.
    assert!((regret_at_1(&[0.1, 0.9, 0.5], &[0.8, 0.6, 0.7]) - 0.2).abs() < 1e-12);
    assert_eq!(regret_at_1(&[1., 2., 3.], &[1., 2., 3.]), 0.0);
}

#[test]
fn clustered_bootstrap_resamples_whole_clusters() {
    use super::bootstrap::{clustered_mean_ci, mean_ci};
    // One cluster: every replicate draws it, so the interval is its mean exactly.
    let one = clustered_mean_ci(&[vec![0.2, 0.4]], 200, 3).unwrap();
    assert!((one[0] - 0.3).abs() < 1e-12 && (one[1] - 0.3).abs() < 1e-12, "{one:?}");
    assert_eq!(clustered_mean_ci(&[vec![], vec![]], 200, 3), None);
    // Deterministic per seed, different across seeds.
    let clusters: Vec<Vec<f64>> = (0..20).map(|i| vec![f64::from(i) / 20.0; 1 + i as usize % 4]).collect();
    let a = clustered_mean_ci(&clusters, 500, 7).unwrap();
    assert_eq!(Some(a), clustered_mean_ci(&clusters, 500, 7));
    assert_ne!(Some(a), clustered_mean_ci(&clusters, 500, 8));
    // Ten clusters of ten equal values: as variable as ten single values, so the
    // interval is far wider than a bootstrap that treats the 100 values as independent:
    // the values' SD is 2.87, so the SE of the mean is 2.87 / √10 = 0.91 by cluster and
    // 2.87 / √100 = 0.29 by value, a ratio of √10 = 3.2 in the widths.
    let ten: Vec<Vec<f64>> = (0..10).map(|i| vec![f64::from(i); 10]).collect();
    let flat: Vec<f64> = ten.iter().flatten().copied().collect();
    let (c, f) = (clustered_mean_ci(&ten, 2000, 1).unwrap(), mean_ci(&flat, 2000, 1).unwrap());
    assert!(c[0] < 4.5 && 4.5 < c[1], "{c:?}");
    assert!(c[1] - c[0] > 2.5 * (f[1] - f[0]), "clustered {c:?} against independent {f:?}");
}

#[test]
fn a_ranking_of_fewer_than_two_policies_reports_no_metrics() {
    // One policy (or none) has no pair to invert: every metric is null, not a perfect 0.
    for (pred, act, names) in [(&[][..], &[][..], &[][..]), (&[0.3][..], &[0.5][..], &["a"][..])] {
        let j = agreement(pred, act).to_json(names, None);
        for key in [
            "pearson",
            "spearman",
            "kendall_tau_b",
            "rank_inversions",
            "rank_inversion_fraction",
            "mmrv",
            "regret_at_1",
        ] {
            assert!(j[key].is_null(), "{key}: {j}");
        }
    }
    // Two policies in the same order: 0 inversions, MMRV 0, regret 0 (defined).
    let j = agreement(&[0.1, 0.2], &[0.3, 0.4]).to_json(&["a", "b"], None);
    assert_eq!((j["rank_inversions"].as_u64(), j["mmrv"].as_f64()), (Some(0), Some(0.0)));
}

#[test]
fn pearson_is_stable_at_extreme_magnitudes() {
    // At 92f9f2b, x = (1e300, -1e300, 0) against y = (1, -1, 0) gave -0.0: every
    // square was infinite. The vectors are exactly proportional, so r = 1; the same
    // for tiny values whose squares underflow to 0 (which gave None).
    let r = pearson(&[1e300, -1e300, 0.0], &[1.0, -1.0, 0.0]).unwrap();
    assert_eq!(r, 1.0);
    let r = pearson(&[1e-200, -1e-200, 0.0], &[-3.0, 3.0, 0.0]).unwrap();
    assert_eq!(r, -1.0);
    // Shifted by 1e15 the scipy example keeps its value to 1e-6 (the shift costs digits).
    let x: Vec<f64> = [1., 2., 3., 4., 5.].iter().map(|v| v + 1e15).collect();
    let r = pearson(&x, &[10., 9., 2.5, 6., 4.]).unwrap();
    assert!((r + 0.7426106572325057).abs() < 1e-6, "{r}");
    assert_eq!(pearson(&[f64::INFINITY, 0.0], &[1.0, 0.0]), None);
    assert_eq!(pearson(&[f64::MAX, -f64::MAX], &[1.0, 0.0]), Some(1.0));
}
