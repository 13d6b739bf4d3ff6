//! The Lift pipeline on tiny settings: collect, a world model that reads 7-D
//! actions, a learned judge of success, diffusion policies that read the commanded
//! pose, and `rank` on all three.

use crate::util::{TinyArm, expect_code, read_json, run, s, tiny_arm_models};

#[test]
fn the_lift_pipeline_collects_trains_every_model_and_ranks() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // 10 short episodes (every 10th is held out): no behaviour lifts the cube in 12 steps.
    let tiny = tiny_arm_models(dir, "lift");
    crate::adapt::a_model_folder_adapted_to_another_rendering_ranks_with_it(dir, &tiny);
    let TinyArm { data, ae, wm, judge, pol, judge_stdout } = tiny;
    // The model reads the task's 7 actions, each in robomimic's [-1, 1].
    let model = &read_json(&wm.join("config.json"))["model"];
    assert_eq!(model["unet"]["action_dim"], 7, "{model}");
    assert_eq!(model["actions"]["low"], serde_json::json!(vec![-1.0; 7]), "{model}");
    assert_eq!(model["actions"]["high"], serde_json::json!(vec![1.0; 7]), "{model}");
    // Action maps draw Push-T's 2-D targets: refused for Lift.
    let maps = dir.join("wm_maps");
    let args = ["train", "world-model", "--data", s(&data), "--autoencoder", s(&ae), "--out", s(&maps)];
    let (_, err) = expect_code(&run(&[&args[..], &["--steps", "1", "--action-maps"]].concat()), 2);
    assert!(err.contains("--action-maps"), "{err}");
    // A judge learns data/success (the label it finds), success above 0.5.
    assert!(judge_stdout.contains("judge of success: held-out 12 frames (0 above 0.5)"), "{judge_stdout}");
    assert_eq!(read_json(&judge.join("judge.json"))["threshold"], 0.5);

    // Policies: 7-D actions and the 7-entry commanded pose, whose range starts at the
    // open gripper (−1) and nothing commanded (0); the encoder is pre-trained on the
    // object's, end effector's and fingers' positions.
    let file = read_json(&pol.join("epoch-0002").join("policy.json"));
    assert_eq!(file["config"]["net"]["action_dim"], 7, "{file}");
    let proprio = &file["normalisation"]["agent_pos"];
    assert_eq!(proprio["min"].as_array().map(Vec::len), Some(7), "{proprio}");
    assert_eq!(proprio["min"][6], -1.0, "{proprio}");
    let pre = &file["provenance"]["encoder_pretraining"];
    assert_eq!(pre["steps"], 2, "{pre}");
    // 10 episodes: none is held out of the pre-training (every 20th), so no error is claimed.
    assert!(pre["heldout_mean_abs_error"].is_null(), "{pre}");

    // MuJoCo alone needs no judge of frames: `simulate --policy` scores a Lift policy exactly
    // (regression: it refused, asking for a judge only the world-model branch uses).
    let (sim, epoch2) = (dir.join("sim"), pol.join("epoch-0002"));
    let args = ["simulate", "--scenario", "lift", "--policy", s(&epoch2), "--episodes", "1"];
    expect_code(&run(&[&args[..], &["--max-steps", "4", "--out", s(&sim)]].concat()), 0);
    let summary = read_json(&sim.join("summary.json"));
    assert_eq!(summary["policies"][0]["mujoco"]["episodes"], 1, "{summary}");

    // `collect --policy` writes the policies' rollouts in the Lift layout: 2 checkpoints ×
    // 1 episode × 3 steps (nothing lifts in 3 steps), which the trainers read as Lift data.
    let col = dir.join("rollouts.zarr");
    let args = ["collect", "--scenario", "lift", "--policy", s(&pol), "--episodes", "1", "--max-steps", "3"];
    let (stdout, _) = expect_code(&run(&[&args[..], &["--out", s(&col)]].concat()), 0);
    assert!(stdout.contains("lift dataset: 2 episodes of 2 checkpoint(s), 6 steps"), "{stdout}");
    let (info, _) = expect_code(&run(&["dataset", "info", s(&col), "--json"]), 0);
    let info: serde_json::Value = serde_json::from_str(&info).unwrap();
    assert_eq!((info["steps"].as_u64(), info["action_dim"].as_u64()), (Some(6), Some(7)), "{info}");
    assert_eq!(info["image"], serde_json::json!([96, 96, 3]), "{info}");
    assert_eq!(info["state_dim"], 23, "{info}");
    assert_eq!(info["score_source"], "data/success", "{info}");
    assert_eq!(info["behaviours"]["epoch-0002"]["episodes"], 1, "{info}");
    let attrs = read_json(&col.join(".zattrs"));
    assert_eq!(attrs["evalharness"]["scenario"], "lift", "{attrs}");
    assert_eq!(attrs["evalharness"]["checkpoints"][1]["name"], "epoch-0002", "{attrs}");

    // `plan` needs a planning cost and copies of the simulator: Lift has neither yet, and
    // is refused by name before anything is written.
    let planned = dir.join("plan");
    let args =
        ["plan", "--scenario", "lift", "--policy", s(&epoch2), "--episodes", "1", "--out", s(&planned)];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("task lift cannot be planned in"), "{err}");
    assert!(!planned.exists());

    // rank the two epochs with this model and judge: both branches run every episode.
    let out = dir.join("rank");
    let args = ["rank", "--scenario", "lift", "--world-model", s(&wm), "--judge", s(&judge)];
    let more = ["--episodes", "2", "--max-steps", "4", "--no-report"];
    let (stdout, _) =
        expect_code(&run(&[&args[..], &more[..], &["--policies", s(&pol), "--out", s(&out)]].concat()), 0);
    // No scene checks in a Lift run: the table shows success rates, not Push-T's columns.
    assert!(stdout.contains("MuJoCo success") && !stdout.contains("block kept"), "{stdout}");
    let res = read_json(&out.join("results.json"));
    assert_eq!(res["policies"].as_array().map(Vec::len), Some(2), "{res}");
    assert_eq!(res["failed_policies"].as_array().map(Vec::len), Some(0), "{res}");
    // The table of tasks reads the run: Lift, 2 policies × 2 episodes from seed 100000.
    let tex = dir.join("tasks.tex");
    let (md, _) = expect_code(&run(&["tasks", s(&out), "--tex", s(&tex)]), 0);
    assert!(md.contains("| lift | 2 × 2 |") && md.contains("| 100000–100001 |"), "{md}");
    assert!(std::fs::read_to_string(&tex).unwrap().contains("lift & 2 & 2 &"));

    // read-judge reads the dataset's episodes as rank reads imagined ones, for each k.
    let (stdout, _) =
        expect_code(&run(&["read-judge", "--judge", s(&judge), "--data", s(&data), "--persist", "1,2"]), 0);
    assert!(
        stdout.contains("| 1 | ") && stdout.contains("| 2 | ") && stdout.contains("of 10 (0 succeed)"),
        "{stdout}"
    );
    // The red-cube rule: nothing lifts in 12 steps, so every episode is read right at every
    // k, and the smallest k wins the tie; its folder holds the rule and no weights.
    let rule = dir.join("rule");
    let read =
        ["read-judge", "--rule", "lift-red", "--data", s(&data), "--persist", "3,1", "--out", s(&rule)];
    let (stdout, _) = expect_code(&run(&read), 0);
    assert!(stdout.contains("| 3 | 10 of 10 (0 succeed) | 0 | 0 |"), "{stdout}");
    assert!(stdout.contains("most episodes read right: k = 1"), "{stdout}");
    let file = read_json(&rule.join("judge.json"));
    assert_eq!((file["kind"].as_str(), file["persist_frames"].as_u64()), (Some("colour_height"), Some(1)));
    assert_eq!(file["rule"]["success_row"], 40, "{file}");
    assert_eq!(file["provenance"]["persistence"]["report"]["best"], 1, "{file}");
    assert!(!rule.join("model.bpk").exists());
    // rank scores the imagined frames with the rule, its persistence set from outside.
    let out = dir.join("rank_rule");
    let ruled =
        ["rank", "--scenario", "lift", "--world-model", s(&wm), "--judge", s(&rule), "--judge-persist", "2"];
    let tiny = ["--episodes", "1", "--max-steps", "4", "--no-report", "--policies", s(&pol)];
    expect_code(&run(&[&ruled[..], &tiny[..], &["--out", s(&out)]].concat()), 0);
    let config = read_json(&out.join("config.json"));
    assert_eq!(config["judge"]["persist_frames"], 2, "{config}");
    // Push-T judges its own frames: a persistence without a judge folder is refused.
    let pusht = ["rank", "--policies", "checkpoints/pusht/policies/epoch-0001", "--judge-persist", "2"];
    let (_, err) = expect_code(&run(&[&pusht[..], &["--out", s(&dir.join("rank_p"))]].concat()), 2);
    assert!(err.contains("--judge-persist"), "{err}");

    // A Push-T policy is refused by name (2-D actions) and reported; nothing is ranked (exit 1).
    let out = dir.join("rank_pusht");
    let more = ["--policies", "checkpoints/pusht/policies/epoch-0001", "--episodes", "1", "--max-steps", "4"];
    expect_code(&run(&[&args[..], &more[..], &["--out", s(&out)]].concat()), 1);
    let res = read_json(&out.join("results.json"));
    let failed = &res["failed_policies"][0];
    assert_eq!(failed["policy"], "epoch-0001");
    assert!(failed["error"].as_str().unwrap().contains("2-D actions, the scenario takes 7-D"), "{res}");
    assert_eq!(res["policies"].as_array().map(Vec::len), Some(0));
}

/// Regression: the trainers named their `--out` folder as the dataset when it held
/// too few episodes; they name the dataset.
#[test]
fn too_few_episodes_name_the_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let data = dir.join("two.zarr");
    let collect = ["collect", "--scenario", "lift", "--episodes", "2", "--max-steps", "2", "--out", s(&data)];
    expect_code(&run(&collect), 0);
    let ae = dir.join("ae");
    let (_, err) =
        expect_code(&run(&["train", "autoencoder", "--data", s(&data), "--out", s(&ae), "--steps", "1"]), 2);
    assert!(err.contains(&format!("dataset {}: 2 episodes: need at least 10", data.display())), "{err}");
}
