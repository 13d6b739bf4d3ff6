//! Models on robomimic Lift data: a world model that reads 7-D actions, a learned
//! judge of success, and the trainers and commands that must refuse Lift for now.

use crate::util::{expect_code, read_json, run};

fn s(p: &std::path::Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_lift_world_model_reads_7d_actions_and_a_judge_learns_success() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // 10 short episodes (every 10th is held out): no behaviour lifts the cube in 12 steps.
    let data = dir.join("lift.zarr");
    let collect =
        ["collect", "--scenario", "lift", "--episodes", "10", "--seed-start", "0", "--max-steps", "12"];
    expect_code(&run(&[&collect[..], &["--out", s(&data)]].concat()), 0);
    let ae = dir.join("ae");
    let args = ["train", "autoencoder", "--data", s(&data), "--out", s(&ae), "--steps", "1", "--batch", "2"];
    expect_code(&run(&args), 0);
    let wm = dir.join("wm");
    let train = ["train", "world-model", "--data", s(&data), "--autoencoder", s(&ae), "--out", s(&wm)];
    let tiny =
        ["--steps", "1", "--base-channels", "16", "--contexts", "2", "--samples", "2", "--eval-every", "1"];
    expect_code(&run(&[&train[..], &tiny[..]].concat()), 0);
    // The model reads the task's 7 actions, each in robomimic's [-1, 1].
    let model = &read_json(&wm.join("config.json"))["model"];
    assert_eq!(model["unet"]["action_dim"], 7, "{model}");
    assert_eq!(model["actions"]["low"], serde_json::json!(vec![-1.0; 7]), "{model}");
    assert_eq!(model["actions"]["high"], serde_json::json!(vec![1.0; 7]), "{model}");
    // Action maps draw Push-T's 2-D targets: refused for Lift.
    let maps = dir.join("wm_maps");
    let args = [&train[..6], &["--out", s(&maps), "--action-maps"], &tiny[..]].concat();
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("--action-maps"), "{err}");
    // A judge learns data/success (the label it finds), success above 0.5.
    let judge = dir.join("judge");
    let args = ["train", "judge", "--data", s(&data), "--out", s(&judge), "--steps", "2", "--batch", "4"];
    let tiny = ["--encoder-width", "8", "--feature-dim", "8"];
    let (stdout, _) = expect_code(&run(&[&args[..], &tiny[..]].concat()), 0);
    assert!(stdout.contains("judge of success: held-out 12 frames (0 above 0.5)"), "{stdout}");
    assert_eq!(read_json(&judge.join("judge.json"))["threshold"], 0.5);

    // The policy trainer reads Push-T's columns: it refuses Lift data by name.
    let pol = dir.join("pol");
    let args = ["train", "policy", "--data", s(&data), "--out", s(&pol), "--epochs", "1"];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("lift dataset") && err.contains("does not train lift policies"), "{err}");
    // rank with this judge and model, but a Push-T policy: the policy is refused by name
    // (2-D actions) and reported, and nothing is ranked (exit 1).
    let out = dir.join("rank");
    let args = ["rank", "--scenario", "lift", "--world-model", s(&wm), "--judge", s(&judge)];
    let more = ["--policies", "checkpoints/pusht/policies/epoch-0001", "--episodes", "1", "--max-steps", "4"];
    let (stdout, _) = expect_code(&run(&[&args[..], &more[..], &["--out", s(&out)]].concat()), 1);
    // No scene checks in a Lift run: the table shows success rates, not Push-T's columns.
    assert!(stdout.contains("MuJoCo success") && !stdout.contains("block kept"), "{stdout}");
    let res = read_json(&out.join("results.json"));
    let failed = &res["failed_policies"][0];
    assert_eq!(failed["policy"], "epoch-0001");
    assert!(failed["error"].as_str().unwrap().contains("2-D actions, the scenario takes 7-D"), "{res}");
    assert_eq!(res["policies"].as_array().map(Vec::len), Some(0));
}
