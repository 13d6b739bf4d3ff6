//! A task that is only its folder and one line of the task table: Reach
//! (`scenarios/reach/`) through `simulate`, `collect`, `train`, `rank` and `report`, as a
//! user would run them. A command that assumed Push-T's poses, coverage or frames, or
//! Lift's and Can's arm, fails here.

use crate::util::{expect_code, read_json, run, s, tree_bytes};

#[test]
fn reach_runs_through_every_command() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();

    // simulate: the expert reaches the goal in every episode, the same bytes for any --jobs.
    let sim = |name: &str, jobs: &str| {
        let out = dir.join(name);
        let args = ["simulate", "--scenario", "reach", "--episodes", "4", "--gif-size", "16", "--jobs", jobs];
        let (stdout, _) = expect_code(&run(&[&args[..], &["--out", s(&out)]].concat()), 0);
        assert!(stdout.contains("reach expert: 4 episodes, success rate 100.0%"), "{stdout}");
        out
    };
    let (one, two) = (sim("sim1", "1"), sim("sim2", "2"));
    assert_eq!(tree_bytes(&one), tree_bytes(&two), "--jobs 1 and --jobs 2 differ");
    let summary = read_json(&one.join("summary.json"));
    assert_eq!(summary["scenario"], "reach");
    assert_eq!(read_json(&one.join("config.json"))["state_columns"], serde_json::json!(["x"]));

    // collect: ten episodes of the default mix run to their step limit (the world model's
    // windows need them long), in the task's layout.
    let data = dir.join("reach.zarr");
    let args = ["collect", "--scenario", "reach", "--episodes", "10", "--seed-start", "0", "--no-early-stop"];
    let (stdout, _) = expect_code(&run(&[&args[..], &["--out", s(&data)]].concat()), 0);
    assert!(stdout.contains("reach dataset: 10 episodes, 200 steps"), "{stdout}");
    let attrs = read_json(&data.join(".zattrs"));
    assert_eq!(attrs["evalharness"]["scenario"], "reach");
    assert_eq!(attrs["evalharness"]["mix"], "expert=0.5,random=0.5");

    // train: an autoencoder, a world model on its latents, and a policy.
    let ae = dir.join("ae");
    let args = ["train", "autoencoder", "--data", s(&data), "--out", s(&ae), "--steps", "1", "--batch", "2"];
    expect_code(&run(&args), 0);
    let wm = dir.join("wm");
    let args = [
        "train",
        "world-model",
        "--data",
        s(&data),
        "--autoencoder",
        s(&ae),
        "--out",
        s(&wm),
        "--steps",
        "2",
        "--base-channels",
        "16",
        "--contexts",
        "2",
        "--samples",
        "2",
        "--eval-every",
        "1",
    ];
    let (stdout, _) = expect_code(&run(&args), 0);
    assert!(stdout.contains("step 2/2"), "{stdout}");
    // The world model reads the task's 1-D actions in the task's bounds, [0, 10].
    let config = read_json(&wm.join("config.json"));
    assert_eq!(config["model"]["actions"]["high"], serde_json::json!([10.0]), "{config}");
    let pol = dir.join("policies");
    let args = [
        "train",
        "policy",
        "--data",
        s(&data),
        "--out",
        s(&pol),
        "--epochs",
        "2",
        "--save-every",
        "1",
        "--behaviour",
        "all",
        "--batch",
        "64",
        "--encoder-width",
        "8",
        "--down-dims",
        "16,32",
        "--inference-steps",
        "2",
        "--encoder-steps",
        "2",
    ];
    let (stdout, _) = expect_code(&run(&args), 0);
    assert!(stdout.contains("epoch-0001") && stdout.contains("epoch-0002"), "{stdout}");
    assert_eq!(read_json(&pol.join("epoch-0001/policy.json"))["task"], "reach");

    // rank: the policy in MuJoCo's place (the task's own simulator) and in the world model,
    // judged by the task's own judge; then its report.
    let out = dir.join("rank");
    let args = [
        "rank",
        "--scenario",
        "reach",
        "--policies",
        s(&pol),
        "--world-model",
        s(&wm),
        "--episodes",
        "3",
        "--batch",
        "3",
        "--max-steps",
        "8",
        "--bootstrap",
        "50",
        "--no-report",
        "--out",
        s(&out),
    ];
    let (stdout, _) = expect_code(&run(&args), 0);
    let results = read_json(&out.join("results.json"));
    assert_eq!(results["scenario"], "reach");
    // Its reference simulator is its own, not MuJoCo (at 8be7ead the table, the report and
    // results.json said MuJoCo for every task).
    assert_eq!(results["simulator"], "simulator");
    assert!(stdout.contains("simulator success") && !stdout.contains("MuJoCo"), "{stdout}");
    let rows = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
    // Two policies (the two epochs), 3 seeds, both branches.
    assert_eq!(rows.lines().count(), 12, "{rows}");
    // The rows name the task's own state (its goal on both branches, the marker's final
    // position in its simulator), none of Push-T's poses or scene checks; so do the tables.
    for line in rows.lines() {
        let row: serde_json::Value = serde_json::from_str(line).unwrap();
        assert_eq!(row["state"]["goal"], 7.0, "{line}");
        assert_eq!(row["state"].get("final_x").is_some(), row["branch"] == "sim", "{line}");
        assert!(row.get("scene").is_none() && row.get("final_block").is_none(), "{line}");
    }
    let table = parquet_columns(&out.join("episodes.parquet"));
    assert!(table.ends_with(&["scorer_abs_error".to_string(), "final_x".into(), "goal".into()]), "{table:?}");
    let (stdout, _) = expect_code(&run(&["report", s(&out)]), 0);
    assert!(stdout.contains("report.html"), "{stdout}");
    // The report states the task's own scoring and judge, not Push-T's coverage.
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(html.contains("An episode's score: 1 if the task succeeded at some step, else 0."), "{html}");
    assert!(html.contains("by the task's own judge"), "{html}");
    assert!(!html.contains("coverage"), "{html}");
    assert!(html.contains("world model vs simulator") && !html.contains("MuJoCo"), "{html}");
}

/// The column names of a run's `episodes.parquet`.
fn parquet_columns(path: &std::path::Path) -> Vec<String> {
    let rows = reports::episodes::read_episodes_parquet(path).unwrap();
    rows[0].get_column_iter().map(|(n, _)| n.clone()).collect()
}
