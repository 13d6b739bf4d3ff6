//! `evalharness agreement --csv`.

use crate::util::{expect_code, run};

#[test]
fn per_policy_csv_gives_hand_computed_metrics() {
    // Three policies, one row each: pred (0.2, 0.5, 0.4), actual (0.1, 0.3, 0.6).
    // MMRV = 0.2 (see harness metrics tests); one inversion (b, c) of 3 pairs; regret:
    // the predictor picks b (0.3) while c reaches 0.6 -> 0.3. No bootstrap with 1 row each.
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("s.csv");
    std::fs::write(&csv, "policy,predicted,actual\na,0.2,0.1\nb,0.5,0.3\nc,0.4,0.6\n").unwrap();
    let (out, _) = expect_code(&run(&["agreement", "--csv", csv.to_str().unwrap()]), 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let ag = &v["agreement"];
    assert!((ag["mmrv"].as_f64().unwrap() - 0.2).abs() < 1e-12);
    assert_eq!(ag["rank_inversions"], 1);
    assert!((ag["regret_at_1"].as_f64().unwrap() - 0.3).abs() < 1e-12);
    assert!(ag["ci95"].is_null());
    assert_eq!(v["policies"][1]["name"], "b");
}

#[test]
fn episode_rows_get_bootstrap_intervals() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("e.csv");
    let mut text = String::from("policy,predicted,actual\n");
    for (p, base) in [("p1", 0.2), ("p2", 0.5), ("p3", 0.8)] {
        for e in 0..6 {
            let d = 0.02 * e as f64;
            text.push_str(&format!("{p},{},{}\n", base + d, base - d / 2.0));
        }
    }
    std::fs::write(&csv, text).unwrap();
    let args = ["agreement", "--csv", csv.to_str().unwrap(), "--bootstrap", "200"];
    let (out, _) = expect_code(&run(&args), 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert!((v["agreement"]["spearman"].as_f64().unwrap() - 1.0).abs() < 1e-12);
    assert_eq!(v["agreement"]["ci95"]["replicates"], 200);
    assert_eq!(v["policies"][0]["rows"], 6);
    // Same seed, same output.
    let (again, _) = expect_code(&run(&args), 0);
    assert_eq!(out, again);
}

#[test]
fn bad_csv_names_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("bad.csv");
    std::fs::write(&csv, "policy,pred,actual\na,1,2\n").unwrap();
    let (_, err) = expect_code(&run(&["agreement", "--csv", csv.to_str().unwrap()]), 2);
    assert!(err.contains("bad.csv") && err.contains("'predicted'"), "{err}");
    std::fs::write(&csv, "policy,predicted,actual\na,1,2\nb,x,3\n").unwrap();
    let (_, err) = expect_code(&run(&["agreement", "--csv", csv.to_str().unwrap()]), 2);
    assert!(err.contains("line 3") && err.contains("'x'"), "{err}");
}
