//! `evalharness import world-model` on the committed DriftWorld fixtures
//! (`world_model/tests/fixtures/driftworld/`, written by `scripts/fixtures/driftworld_wm.py`).

use std::path::{Path, PathBuf};

use crate::util::{expect_code, pusht_inputs, read_json, run, s, tiny_rank_args, tree_bytes, with_flag};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("world_model/tests/fixtures/driftworld").join(name)
}

fn import(file: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["import", "world-model", "--format", "driftworld", s(file), "--out", s(out)];
    args.extend(extra);
    run(&args)
}

/// The 32-channel fixture imported at Push-T's 96² frames (a convolutional network runs at any
/// size), then a tiny `rank` of two scripted policies with it, `extra` flags added: exit 0.
fn rank_with_imported_model(dir: &Path, extra: &[&str]) -> PathBuf {
    let (set, _) = pusht_inputs(dir);
    let wm = dir.join("wm");
    expect_code(&import(&fixture("wm.pth"), &wm, &[]), 0);
    let rank_out = dir.join("rank");
    let args = tiny_rank_args(&set, &wm, &rank_out);
    let args = with_flag(&args, "--episodes", "2");
    expect_code(&run(&[&args[..], extra].concat()), 0);
    rank_out
}

#[test]
fn a_driftworld_checkpoint_becomes_a_world_model_folder_that_rank_runs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("imported");
    let (stdout, _) = expect_code(&import(&fixture("wm.pth"), &out, &["--image-size", "16"]), 0);
    assert_eq!(stdout.trim(), out.display().to_string());
    let cfg = read_json(&out.join("config.json"));
    assert_eq!(cfg["model"]["unet"]["frame_attention_norm"], true);
    assert_eq!(cfg["model"]["unet"]["model_channels"], 32);
    assert_eq!(cfg["model"]["latents"]["size"], 16);
    assert_eq!(cfg["model"]["future"], 4);
    assert_eq!(cfg["import"]["step"], 4321);
    assert_eq!(cfg["import"]["tensors"], 436);
    let prov = read_json(&out.join("provenance.json"));
    assert!(prov["import"]["sha256"].as_str().is_some_and(|h| h.starts_with("sha256:")), "{prov}");
    assert!(out.join("ema.bpk").is_file());

    // The same weights at Push-T's 96² frames rank policies end to end.
    let rank_out = rank_with_imported_model(dir.path(), &[]);
    let results = read_json(&rank_out.join("results.json"));
    assert!(results["timing"]["world_model_ms_per_frame"].as_f64().is_some_and(|v| v > 0.0), "{results}");
}

#[test]
fn a_damaged_checkpoint_is_refused_by_key_and_the_existing_folder_is_kept() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("imported");
    expect_code(&import(&fixture("micro.pth"), &out, &[]), 0);
    let before = tree_bytes(&out);
    // Without --force an existing folder is never replaced.
    let (_, err) = expect_code(&import(&fixture("micro.pth"), &out, &[]), 2);
    assert!(err.contains("--force"), "{err}");
    for (file, key) in [
        ("micro_missing_key.pth", "model.ema_model.middle_block.0.in_layers.0.weight"),
        ("micro_wrong_shape.pth", "model.ema_model.middle_block.0.emb_layers.1.weight"),
        ("micro_float64.pth", "model.ema_model.out.0.weight"),
        ("micro_qkv_swapped.pth", "model.ema_model.middle_block.1.qkv.weight"),
        ("micro_unexpected_key.pth", "model.ema_model.middle_block.1.extra.weight"),
    ] {
        let (_, err) = expect_code(&import(&fixture(file), &out, &["--force"]), 2);
        assert!(err.contains(key) && err.contains(file), "{file}: {err}");
        assert_eq!(tree_bytes(&out), before, "{file} changed the existing folder");
    }
    assert!(!dir.path().join("imported.partial").exists());
}

#[test]
fn gpc_reward_predictors_become_a_judge_that_rank_uses_with_an_imported_world_model() {
    let dir = tempfile::tempdir().unwrap();
    let reward = Path::new(env!("CARGO_MANIFEST_DIR")).join("judges/tests/fixtures/gpc_reward");
    let judge = dir.path().join("judge");
    let (xy, angle) = (reward.join("reward_predictor_xy.pth"), reward.join("reward_predictor_angle.pth"));
    let args = ["import", "judge", "--format", "gpc-reward-predictor", "--xy", s(&xy), "--angle", s(&angle)];
    let (stdout, _) = expect_code(&run(&[&args[..], &["--out", s(&judge)]].concat()), 0);
    assert_eq!(stdout.trim(), judge.display().to_string());
    let file = read_json(&judge.join("judge.json"));
    assert_eq!((file["kind"].as_str(), file["pose_base"].as_u64()), (Some("gpc_pose"), Some(8)));
    assert!(file["provenance"]["import"]["xy"]["sha256"].as_str().is_some_and(|h| h.starts_with("sha256:")));
    // A missing key: refused by name, nothing written.
    let bad = reward.join("reward_missing_key.pth");
    let other = dir.path().join("other");
    let bad_args =
        ["import", "judge", "--format", "gpc-reward-predictor", "--xy", s(&bad), "--angle", s(&angle)];
    let (_, err) = expect_code(&run(&[&bad_args[..], &["--out", s(&other)]].concat()), 2);
    assert!(err.contains("resnet18.5.0.downsample.1.running_var"), "{err}");
    assert!(!other.exists());

    // rank with the imported world model and judge on GPC's Push-T (its resets and frames):
    // every imagined and real frame judged by pose, the real frames' reading error against
    // the exact coverage reported.
    let rank_out = rank_with_imported_model(dir.path(), &["--judge", s(&judge), "--scenario", "pusht-gpc"]);
    let cfg = read_json(&rank_out.join("config.json"));
    assert_eq!(cfg["scenario"], "pusht-gpc", "{cfg}");
    let rows = std::fs::read_to_string(rank_out.join("episodes.jsonl")).unwrap();
    let first: serde_json::Value = serde_json::from_str(rows.lines().next().unwrap()).unwrap();
    let err = first["scorer_abs_error"].as_f64();
    assert!(err.is_some_and(|e| (0.0..=1.0).contains(&e)), "{first}");

    // plan ranks proposals by the imported judge (GPC-RANK's reward predictors), with the
    // imported world model imagining them.
    let (planned, wm) = (dir.path().join("plan"), dir.path().join("wm"));
    let args = ["plan", "--scenario", "pusht-gpc", "--world-model", s(&wm), "--judge", s(&judge)];
    let tiny = ["--planners", "world-model", "--episodes", "1", "--max-steps", "4", "--proposals", "2"];
    let tiny = [&tiny[..], &["--imagine", "4", "--execute", "4"]].concat();
    expect_code(&run(&[&args[..], &tiny[..], &["--bootstrap", "20", "--out", s(&planned)]].concat()), 0);
    let cfg = read_json(&planned.join("config.json"));
    assert_eq!(cfg["cost"], "1 - the judge's score of the last imagined frame", "{cfg}");
    assert!(cfg["fingerprints"]["judge"].is_string(), "{cfg}");
    let res = read_json(&planned.join("results.json"));
    assert_eq!(res["planners"]["world-model"]["episodes"], 1, "{res}");
}

#[test]
fn judging_every_imagined_frame_reads_a_superset_of_the_frames_and_is_part_of_the_run() {
    // The same episodes with the frames the policy sees judged, and with every generated frame
    // judged (the official loop): the generated frames are the same (same noise streams), so
    // each imagined episode's best score can only rise; the MuJoCo rows are the same.
    let dir = tempfile::tempdir().unwrap();
    let (set, wm) = pusht_inputs(dir.path());
    let (seen, every) = (dir.path().join("seen"), dir.path().join("every"));
    expect_code(&run(&tiny_rank_args(&set, &wm, &seen)), 0);
    let args = [&tiny_rank_args(&set, &wm, &every)[..], &["--judge-every-frame"]].concat();
    expect_code(&run(&args), 0);
    let rows = |d: &Path| -> Vec<serde_json::Value> {
        let text = std::fs::read_to_string(d.join("episodes.jsonl")).unwrap();
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    };
    let (a, b) = (rows(&seen), rows(&every));
    assert_eq!(a.len(), b.len());
    let mut rose = 0;
    for (x, y) in a.iter().zip(&b) {
        assert_eq!((&x["policy"], &x["seed"], &x["branch"]), (&y["policy"], &y["seed"], &y["branch"]));
        let (sx, sy) = (x["score"].as_f64().unwrap(), y["score"].as_f64().unwrap());
        if x["branch"] == "sim" {
            assert_eq!(x, y, "the MuJoCo branch does not depend on the flag");
        } else {
            assert!(sy >= sx, "{x}\n{y}");
            rose += usize::from(sy > sx);
        }
    }
    eprintln!("{rose} imagined episodes scored higher with every frame judged");
    assert_eq!(read_json(&every.join("config.json"))["judge_every_frame"], true);
    assert!(read_json(&seen.join("config.json")).get("judge_every_frame").is_none());
    // A resume without the flag would mix two ways of judging: refused.
    let resume = [&tiny_rank_args(&set, &wm, &every)[..], &["--resume"]].concat();
    let (_, err) = expect_code(&run(&resume), 2);
    assert!(err.contains("judge_every_frame"), "{err}");
}

#[test]
fn gpc_and_lerobot_policies_become_checkpoints_that_rank_runs() {
    // policies/tests/fixtures/gpc_policy/policy.pth: GPC's checkpoint layout at a reduced size
    // (scripts/fixtures/gpc_policy.py). Imported, it ranks beside a scripted policy on GPC's
    // Push-T with the imported world model; a file that is not a policy is refused by key.
    let dir = tempfile::tempdir().unwrap();
    // Named as GPC names its checkpoints, which is where the epoch is read from.
    let file = dir.path().join("ckpt-ep50.pth");
    let fixture_file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("policies/tests/fixtures/gpc_policy/policy.pth");
    std::fs::copy(fixture_file, &file).unwrap();
    let (set, _) = pusht_inputs(dir.path());
    let pol = set.join("ckpt-ep50");
    let args = ["import", "policy", "--format", "gpc", s(&file), "--out", s(&pol)];
    let (stdout, _) = expect_code(&run(&args), 0);
    assert_eq!(stdout.trim(), pol.display().to_string());
    let p = read_json(&pol.join("policy.json"));
    assert_eq!(
        (p["kind"].as_str(), p["step"].as_u64(), p["epoch"].as_u64()),
        (Some("gpc-diffusion"), Some(4242), Some(50))
    );
    assert!(p["provenance"]["import"]["sha256"].as_str().is_some_and(|h| h.starts_with("sha256:")), "{p}");
    assert!(p.get("train_loss").is_none(), "an imported checkpoint states no loss: {p}");
    // Refused without --force, and a world-model file is refused naming what it lacks.
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("--force"), "{err}");
    let wm_file = fixture("micro.pth");
    let other = dir.path().join("other");
    let (_, err) =
        expect_code(&run(&["import", "policy", "--format", "gpc", s(&wm_file), "--out", s(&other)]), 2);
    assert!(err.contains("micro.pth") && err.contains("model."), "{err}");
    assert!(!other.exists());
    // Each format says what it reads when given the other kind of path.
    let empty = tempfile::tempdir().unwrap();
    let (_, err) =
        expect_code(&run(&["import", "policy", "--format", "gpc", s(empty.path()), "--out", s(&other)]), 2);
    assert!(err.contains("vision_encoder.pth (GPC's folder layout)"), "{err}");
    // Statistics of one's own (GPC's files carry none): recorded with their SHA-256; a file of
    // the wrong widths is refused naming it, nothing written.
    let stats = dir.path().join("stats.json");
    let own =
        r#"{"agent_pos": {"min": [0, 0], "max": [500, 500]}, "action": {"min": [1, 1], "max": [510, 510]}}"#;
    std::fs::write(&stats, own).unwrap();
    let with_stats = dir.path().join("with-stats");
    let args =
        ["import", "policy", "--format", "gpc", s(&file), "--stats", s(&stats), "--out", s(&with_stats)];
    expect_code(&run(&args), 0);
    let p = read_json(&with_stats.join("policy.json"));
    assert_eq!(p["normalisation"]["action"]["max"], serde_json::json!([510.0, 510.0]), "{p}");
    assert!(
        p["provenance"]["import"]["normalisation"]["sha256"]
            .as_str()
            .is_some_and(|h| h.starts_with("sha256:")),
        "{p}"
    );
    std::fs::write(&stats, own.replace("[1, 1]", "[1]")).unwrap();
    let refused = dir.path().join("refused");
    let args = ["import", "policy", "--format", "gpc", s(&file), "--stats", s(&stats), "--out", s(&refused)];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("stats.json") && err.contains("action 2 finite (min, max) pairs"), "{err}");
    assert!(!refused.exists());
    // GPC's folder layout of the same networks imports to the same checkpoint.
    let folder = Path::new(env!("CARGO_MANIFEST_DIR")).join("policies/tests/fixtures/gpc_policy/official");
    let from_folder = dir.path().join("from-folder");
    expect_code(&run(&["import", "policy", "--format", "gpc", s(&folder), "--out", s(&from_folder)]), 0);
    // (The unit test `gpcs_folder_layout_imports_to_the_same_networks` compares the outputs.)
    let p = read_json(&from_folder.join("policy.json"));
    assert_eq!(p["config"], read_json(&pol.join("policy.json"))["config"], "{p}");
    assert_eq!(p["step"], 4242, "{p}");
    assert!(
        p["provenance"]["import"]["sha256"]["ema_nets.pth"]
            .as_str()
            .is_some_and(|h| h.starts_with("sha256:")),
        "{p}"
    );
    let (_, err) =
        expect_code(&run(&["import", "policy", "--format", "lerobot", s(&file), "--out", s(&other)]), 2);
    assert!(err.contains("reads a pretrained_model folder"), "{err}");

    // A LeRobot policy folder (its statistics in the preprocessor's file) beside it.
    let lerobot = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("policies/tests/fixtures/lerobot_policy/pretrained_model_processors");
    let lr = set.join("lerobot-pusht");
    expect_code(&run(&["import", "policy", "--format", "lerobot", s(&lerobot), "--out", s(&lr)]), 0);
    let p = read_json(&lr.join("policy.json"));
    assert_eq!(p["kind"], "lerobot-diffusion", "{p}");
    assert_eq!(p["config"]["pool"]["spatial-softmax"]["keypoints"], 4, "{p}");
    assert!(
        p["provenance"]["import"]["statistics"]["source"].as_str().is_some_and(|s| s.contains("normalizer")),
        "{p}"
    );

    // One with torchvision's BatchNorms (`use_group_norm: false`), folded at import.
    let bn = set.join("lerobot-bn");
    let src = lerobot.with_file_name("pretrained_model_bn");
    expect_code(&run(&["import", "policy", "--format", "lerobot", s(&src), "--out", s(&bn)]), 0);
    let p = read_json(&bn.join("policy.json"));
    assert_eq!(p["config"]["backbone_norm"], "folded-batch", "{p}");

    // One resizing its frames before the crop (LeRobot 0.4's `resize_shape` and `crop_ratio`).
    let rs = set.join("lerobot-resize");
    let src = lerobot.with_file_name("pretrained_model_resize");
    expect_code(&run(&["import", "policy", "--format", "lerobot", s(&src), "--out", s(&rs)]), 0);
    let p = read_json(&rs.join("policy.json"));
    let c = &p["config"];
    assert_eq!(
        (&c["input_size"], &c["antialias"], &c["crop"]),
        (&72.into(), &true.into(), &64.into()),
        "{p}"
    );

    let wm = dir.path().join("wm");
    expect_code(&import(&fixture("wm.pth"), &wm, &[]), 0);
    let out = dir.path().join("rank");
    let args = tiny_rank_args(&set, &wm, &out);
    let args = with_flag(&with_flag(&args, "--episodes", "2"), "--max-steps", "4");
    expect_code(&run(&[&args[..], &["--scenario", "pusht-gpc"]].concat()), 0);
    let rows = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
    for name in ["\"ckpt-ep50\"", "\"lerobot-pusht\"", "\"lerobot-bn\"", "\"lerobot-resize\""] {
        let n = rows.lines().filter(|l| l.contains(name)).count();
        assert_eq!(n, 4, "{name}: two episodes in each branch:\n{rows}");
    }

    // The official loop's float frames: the imported policies read the world model's frames
    // before rounding; the run records it.
    let floats = dir.path().join("rank_floats");
    let args = tiny_rank_args(&set, &wm, &floats);
    let args = with_flag(&with_flag(&args, "--episodes", "2"), "--max-steps", "4");
    expect_code(&run(&[&args[..], &["--scenario", "pusht-gpc", "--float-frames"]].concat()), 0);
    assert_eq!(read_json(&floats.join("config.json"))["float_frames"], true);
    // A goal-free world model draws the goal back onto bytes: refused with the flag.
    let (_, err) = expect_code(
        &run(&[
            &tiny_rank_args(
                &set,
                Path::new(crate::util::PUSHT).join("world_model").as_path(),
                &dir.path().join("gf"),
            )[..],
            &["--float-frames"],
        ]
        .concat()),
        2,
    );
    assert!(err.contains("--float-frames") && err.contains("goal-free"), "{err}");

    // GPC-RANK with GPC's own proposer: plan takes the imported policy.
    let planned = dir.path().join("plan");
    let args = ["plan", "--scenario", "pusht-gpc", "--policy", s(&pol), "--world-model", s(&wm)];
    let tiny = ["--planners", "world-model", "--episodes", "1", "--max-steps", "4", "--proposals", "2"];
    let more = ["--imagine", "4", "--execute", "4", "--bootstrap", "20", "--out", s(&planned)];
    expect_code(&run(&[&args[..], &tiny[..], &more[..]].concat()), 0);
    let res = read_json(&planned.join("results.json"));
    assert_eq!(res["planners"]["world-model"]["episodes"], 1, "{res}");
}

#[test]
fn a_robomimic_policy_ranks_beside_native_ones_on_lift_and_can() {
    // policies/tests/fixtures/robomimic_policy/policy.pth: robomimic's checkpoint layout at a
    // reduced size (scripts/fixtures/robomimic_policy.py), agentview at 84² plus the robot's
    // eef position, orientation and finger joints. Imported for Lift (its env_name) and, named,
    // for Can; each ranks beside the task's weakest shipped policy, and GPC's Push-T policy
    // in the same folder is reported in failed_policies by name while the others rank.
    let dir = tempfile::tempdir().unwrap();
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("policies/tests/fixtures");
    let file = fixtures.join("robomimic_policy/policy.pth");
    let gpc = fixtures.join("gpc_policy/policy.pth");
    for task in ["lift", "can"] {
        let set = dir.path().join(task);
        let pol = set.join("robomimic");
        let mut args = vec!["import", "policy", "--format", "robomimic", s(&file), "--out", s(&pol)];
        if task == "can" {
            args.extend(["--scenario", "can"]);
        }
        expect_code(&run(&args), 0);
        let p = read_json(&pol.join("policy.json"));
        assert_eq!(
            (p["kind"].as_str(), p["task"].as_str(), p["epoch"].as_u64()),
            (Some("robomimic-diffusion"), Some(task), Some(120))
        );
        assert_eq!(p["config"]["robot_keys"][2], "robot0_gripper_qpos", "{p}");
        assert_eq!(p["provenance"]["import"]["weights"], "model.ema", "{p}");
        let weakest = if task == "lift" { "epoch-0014" } else { "epoch-0006" };
        let native =
            Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("checkpoints/{task}/policies/{weakest}"));
        crate::util::copy_dir(&native, &set.join(weakest));
        expect_code(
            &run(&["import", "policy", "--format", "gpc", s(&gpc), "--out", s(&set.join("gpc-pusht"))]),
            0,
        );
        let out = dir.path().join(format!("rank-{task}"));
        let args = ["rank", "--scenario", task, "--policies", s(&set), "--episodes", "2", "--batch", "2"];
        let more = ["--max-steps", "16", "--bootstrap", "10", "--no-report", "--out", s(&out)];
        // Two policies rank; with two, the gates may pass or fail: not an error.
        let res = run(&[&args[..], &more[..]].concat());
        let err = String::from_utf8_lossy(&res.stderr);
        assert!(matches!(res.status.code(), Some(0 | 1)), "{task}: {err}");
        let rows = std::fs::read_to_string(out.join("episodes.jsonl")).unwrap();
        for name in ["\"robomimic\"".to_string(), format!("\"{weakest}\"")] {
            assert_eq!(
                rows.lines().filter(|l| l.contains(name.as_str())).count(),
                4,
                "{task} {name}: two episodes per branch:\n{rows}"
            );
        }
        let res = read_json(&out.join("results.json"));
        let failed = &res["failed_policies"];
        assert_eq!(failed.as_array().map(Vec::len), Some(1), "{res}");
        assert_eq!(failed[0]["policy"], "gpc-pusht", "{res}");
    }
    // A key no scene gives is refused naming it, before anything is written; so is a camera
    // the world model cannot imagine.
    let bad = dir.path().join("bad");
    let refused = |name: &str| {
        let file = fixtures.join("robomimic_policy").join(name);
        expect_code(&run(&["import", "policy", "--format", "robomimic", s(&file), "--out", s(&bad)]), 2).1
    };
    let err = refused("object_key.pth");
    assert!(err.contains("`object`") && err.contains("robot0_eef_pos"), "{err}");
    let err = refused("eye_in_hand.pth");
    assert!(err.contains("robot0_eye_in_hand_image"), "{err}");
    assert!(!bad.exists());
}
