//! `evalharness train autoencoder` and `train policy` on tiny datasets: outputs, resume, bad
//! input (`train world-model` in [`super::train_wm`]).

use std::path::Path;

use crate::util::{expect_code, read_json, run, scenario_variant};

/// 10 short explorer episodes (episode 9 is the held-out one).
pub(crate) fn tiny_dataset(dir: &Path, scenario: Option<&Path>) -> std::path::PathBuf {
    let out = dir.join("tiny.zarr");
    let mut args =
        vec!["collect", "--episodes", "10", "--seed-start", "0", "--max-steps", "4", "--mix", "explore=1"];
    if let Some(s) = scenario {
        args.extend(["--scenario", s.to_str().unwrap()]);
    }
    args.extend(["--out", out.to_str().unwrap()]);
    expect_code(&run(&args), 0);
    out
}

#[test]
fn autoencoder_trains_checkpoints_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let out = dir.path().join("ae");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let base = [
        "train",
        "autoencoder",
        "--data",
        d,
        "--out",
        o,
        "--batch",
        "2",
        "--eval-every",
        "1",
        "--checkpoint-every",
        "1",
    ];
    let mut first = base.to_vec();
    first.extend(["--steps", "2"]);
    let (stdout, _) = expect_code(&run(&first), 0);
    assert!(stdout.contains("step 2/2"), "{stdout}");
    let prov = read_json(&out.join("provenance.json"));
    assert_eq!(prov["steps"], 2);
    assert_eq!(prov["finished"], true);
    assert_eq!(prov["data"]["episodes"], 10);
    assert!(prov["metrics"]["held_out_psnr_db"].as_f64().unwrap().is_finite());
    for f in
        ["model.bpk", "optimizer.bpk", "state.json", "train_log.jsonl", "reconstructions.png", "config.json"]
    {
        assert!(out.join(f).is_file(), "missing {f}");
    }
    // Without --resume an existing run is refused.
    let (_, err) = expect_code(&run(&first), 2);
    assert!(err.contains("--resume"), "{err}");
    // Resuming a finished run without --steps trains nothing more (the saved config wins).
    let mut again = base.to_vec();
    again.push("--resume");
    let (stdout, _) = expect_code(&run(&again), 0);
    assert!(stdout.contains("step 2/2"), "{stdout}");
    // --resume --steps 3 extends it by exactly one step.
    again.extend(["--steps", "3"]);
    let (stdout, _) = expect_code(&run(&again), 0);
    assert!(stdout.contains("step 3/3"), "{stdout}");
    let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    let steps: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap()["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, vec![1, 2, 3]);
    // A flag that contradicts the saved run is refused rather than ignored.
    let batch: Vec<&str> = again.iter().map(|&a| if a == "2" { "8" } else { a }).collect();
    let (_, err) = expect_code(&run(&batch), 2);
    assert!(err.contains("--batch (saved: 2)"), "{err}");
}

#[test]
fn autoencoder_rejects_a_dataset_of_the_wrong_image_size() {
    let dir = tempfile::tempdir().unwrap();
    let small = scenario_variant(dir.path(), "small.toml", "size = 96 ", "size = 64 ");
    let data = tiny_dataset(dir.path(), Some(&small));
    let out = dir.path().join("ae");
    let args = [
        "train",
        "autoencoder",
        "--data",
        data.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--steps",
        "1",
    ];
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("tiny.zarr") && err.contains("64x64") && err.contains("96x96"), "{err}");
}

/// A policy run stopped during the encoder's pose pre-training resumes from there.
#[test]
fn policy_stopped_during_encoder_pretraining_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let out = dir.path().join("pol");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let base = [
        "train",
        "policy",
        "--data",
        d,
        "--out",
        o,
        "--behaviour",
        "all",
        "--epochs",
        "1",
        "--batch",
        "40",
        "--encoder-width",
        "8",
        "--down-dims",
        "16,32",
        "--encoder-steps",
        "2",
    ];
    let mut first = base.to_vec();
    first.extend(["--max-minutes", "0"]);
    let (stdout, _) = expect_code(&run(&first), 0);
    assert!(stdout.contains("step 0/1 (stopped early"), "{stdout}");
    assert!(!out.join("epoch-0001").exists());
    let mut again = base.to_vec();
    again.push("--resume");
    let (stdout, _) = expect_code(&run(&again), 0);
    assert!(stdout.contains("step 1/1") && stdout.contains("epoch-0001"), "{stdout}");
    let state = read_json(&out.join(".train/encoder_state.json"));
    assert_eq!(state["step"], 2);
    // Each session is recorded: the first ended at step 0 (out of time), the second at 1.
    let sessions = std::fs::read_to_string(out.join(".train/sessions.jsonl")).unwrap();
    let steps: Vec<(u64, u64)> = sessions
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|v| (v["from_step"].as_u64().unwrap(), v["to_step"].as_u64().unwrap()))
        .collect();
    assert_eq!(steps, vec![(0, 0), (0, 1)]);
    assert!(sessions.lines().nth(1).unwrap().contains("--resume"), "{sessions}");
    assert!(!out.join(".train/session_open.json").exists());
    let file = read_json(&out.join("epoch-0001/policy.json"));
    assert_eq!(file["provenance"]["encoder_pretraining"]["steps"], 2, "{file}");
    // Checkpoints come from the weights' moving average (on by default), kept with the state.
    assert_eq!(file["provenance"]["weights"]["ema_decay"], 0.999, "{file}");
    assert_eq!(file["provenance"]["weights"]["ema_updates"], 1, "{file}");
    assert!(out.join(".train/ema.bpk").is_file());
    // Extending the run with the EMA switched off saves the raw weights, and says so.
    let mut args: Vec<&str> = base.iter().copied().filter(|a| *a != "--epochs" && *a != "1").collect();
    args.extend(["--resume", "--epochs", "2", "--ema", "0"]);
    let (stdout, _) = expect_code(&run(&args), 0);
    assert!(stdout.contains("epoch-0002"), "{stdout}");
    let file = read_json(&out.join("epoch-0002/policy.json"));
    assert_eq!(file["provenance"]["weights"], "raw", "{file}");
    assert!(file["provenance"]["resumed_with"].as_str().unwrap().contains("--ema 0"), "{file}");
    // Changing the network on --resume is refused, naming the flag and the saved value.
    let wider: Vec<&str> = args.iter().map(|&a| if a == "8" { "12" } else { a }).collect();
    let (_, err) = expect_code(&run(&wider), 2);
    assert!(err.contains("--encoder-width (saved: 8)"), "{err}");

    // export-policies: chosen epochs into a set, with other inference settings.
    let set = dir.path().join("set");
    let export = ["export-policies", "--from", o, "--out", set.to_str().unwrap()];
    let (stdout, _) =
        expect_code(&run(&[&export[..], &["--epochs", "2", "--action-horizon", "4"]].concat()), 0);
    assert!(stdout.trim().ends_with("epoch-0002"), "{stdout}");
    assert!(!set.join("epoch-0001").exists());
    let copy = read_json(&set.join("epoch-0002/policy.json"));
    assert_eq!(copy["config"]["action_horizon"], 4);
    assert_eq!(copy["provenance"]["exported"][0]["changed"]["action_horizon"], serde_json::json!([8, 4]));
    let weights = |d: &Path| std::fs::read(d.join("epoch-0002/model.bpk")).unwrap();
    assert_eq!(weights(&set), weights(&out));
    // The copy runs; bad requests name the problem.
    let sim = ["simulate", "--policy", set.to_str().unwrap(), "--episodes", "1", "--max-steps", "8"];
    let sim_out = dir.path().join("sim");
    expect_code(&run(&[&sim[..], &["--record-scores", "--out", sim_out.to_str().unwrap()]].concat()), 0);
    // Re-exporting unchanged keeps the measured score and the export history.
    let again = dir.path().join("again");
    let (a, s) = (again.to_str().unwrap(), set.to_str().unwrap());
    expect_code(&run(&["export-policies", "--from", s, "--out", a, "--action-horizon", "4"]), 0);
    let prov = read_json(&again.join("epoch-0002/provenance.json"));
    assert!(prov["mujoco_score"]["mean"].is_number(), "{prov}");
    assert_eq!(prov["training"]["exported"].as_array().unwrap().len(), 2, "{prov}");
    assert_eq!(prov["training"]["exported"][1]["changed"], serde_json::json!({}), "{prov}");
    let (_, err) = expect_code(&run(&[&export[..], &["--force", "--epochs", "7"]].concat()), 2);
    assert!(err.contains("no checkpoint of epoch 7"), "{err}");
    let (_, err) = expect_code(&run(&[&export[..], &["--force", "--action-horizon", "16"]].concat()), 2);
    assert!(err.contains("--action-horizon 16 must be 1..=15"), "{err}");

    // Fine-tuning a checkpoint: its network, action horizon and normalisation carry
    // over, its provenance nests in the new one's, and typed sizes must agree with it.
    let tuned = dir.path().join("tuned");
    let start = set.join("epoch-0002");
    let tune = [
        "train",
        "policy",
        "--data",
        d,
        "--behaviour",
        "all",
        "--batch",
        "40",
        "--init-from",
        start.to_str().unwrap(),
        "--out",
        tuned.to_str().unwrap(),
    ];
    let (stdout, _) = expect_code(&run(&[&tune[..], &["--epochs", "1"]].concat()), 0);
    assert!(stdout.contains("step 1/1") && stdout.contains("epoch-0001"), "{stdout}");
    let file = read_json(&tuned.join("epoch-0001/policy.json"));
    assert_eq!(file["config"], copy["config"], "{file}");
    // The same f32 ranges (the export wrote them through f64).
    let ranges = |v: &serde_json::Value| -> Vec<f32> {
        ["action", "agent_pos"]
            .iter()
            .flat_map(|k| ["min", "max"].map(|m| v["normalisation"][k][m].clone()))
            .flat_map(|a| (0..2).map(move |i| a[i].as_f64().unwrap() as f32))
            .collect()
    };
    assert_eq!(ranges(&file), ranges(&copy), "{file}");
    assert_eq!(file["provenance"]["init_from"]["epoch"], 2, "{file}");
    assert_eq!(file["provenance"]["init_from"]["provenance"], copy["provenance"], "{file}");
    assert!(file["provenance"].get("encoder_pretraining").is_none(), "{file}");
    let (stdout, _) = expect_code(&run(&[&tune[..], &["--resume", "--epochs", "2"]].concat()), 0);
    assert!(stdout.contains("epoch-0002"), "{stdout}");
    let (_, err) = expect_code(&run(&[&tune[..], &["--force", "--down-dims", "16,64"]].concat()), 2);
    assert!(err.contains("its U-Net has channels [16, 32], not [16, 64]"), "{err}");
    assert!(tuned.join("epoch-0002/model.bpk").is_file(), "a refused --force run keeps the old output");
    let (_, err) = expect_code(&run(&[&tune[..], &["--force", "--encoder-steps", "5"]].concat()), 2);
    assert!(err.contains("--encoder-steps"), "{err}");
    // The fine-tuned epochs join the set they started from, under a prefix.
    let (t, st) = (tuned.to_str().unwrap(), set.to_str().unwrap());
    let add = ["export-policies", "--from", t, "--epochs", "1", "--prefix", "ft-", "--add", "--out", st];
    let (stdout, _) = expect_code(&run(&add), 0);
    assert!(stdout.trim().ends_with("ft-epoch-0001"), "{stdout}");
    assert!(set.join("epoch-0002/model.bpk").is_file() && set.join("ft-epoch-0001/model.bpk").is_file());
    let (_, err) = expect_code(&run(&add), 2);
    assert!(err.contains("already holds ft-epoch-0001"), "{err}");
    assert!(!dir.path().join("set.partial").exists());
    let nowhere = dir.path().join("nowhere");
    let (_, err) = expect_code(&run(&[&add[..9], &[nowhere.to_str().unwrap()]].concat()), 2);
    assert!(err.contains("is not an existing policy set"), "{err}");
    let other = out.join("epoch-0002");
    let elsewhere: Vec<&str> = tune
        .iter()
        .map(|&a| if a == start.to_str().unwrap() { other.to_str().unwrap() } else { a })
        .collect();
    let (_, err) = expect_code(&run(&[&elsewhere[..], &["--resume"]].concat()), 2);
    assert!(err.contains("--init-from (saved: "), "{err}");
    let scripted = dir.path().join("scripted");
    expect_code(&run(&["scripted", "--out", scripted.to_str().unwrap()]), 0);
    let (_, err) =
        expect_code(&run(&["export-policies", "--from", scripted.to_str().unwrap(), "--out", a]), 2);
    assert!(err.contains("kind \"scripted\": only diffusion checkpoints"), "{err}");
}

#[test]
fn an_interrupted_run_saves_and_resumes() {
    use std::process::Stdio;
    use std::time::{Duration, Instant};
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let out = dir.path().join("ae");
    let (d, o) = (data.to_str().unwrap(), out.to_str().unwrap());
    let args = ["train", "autoencoder", "--data", d, "--out", o, "--batch", "2", "--steps", "100000"];
    let child = crate::util::evalharness()
        .args(args)
        .args(["--eval-every", "100000", "--checkpoint-every", "1000"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait until training has started (the log gets its first line), then press Ctrl-C.
    let t0 = Instant::now();
    while std::fs::read_to_string(out.join("train_log.jsonl")).map_or(true, |t| t.is_empty()) {
        assert!(t0.elapsed() < Duration::from_secs(300), "training never started");
        std::thread::sleep(Duration::from_millis(100));
    }
    let status = std::process::Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let (stdout, _) = expect_code(&child.wait_with_output().unwrap(), 0);
    assert!(stdout.contains("stopped early; --resume continues"), "{stdout}");
    // The step in progress was finished and saved, though no periodic checkpoint was due.
    let prov = read_json(&out.join("provenance.json"));
    assert_eq!(prov["finished"], false);
    let steps = prov["steps"].as_u64().unwrap();
    assert!((1..100_000).contains(&steps), "{steps}");
    assert_eq!(read_json(&out.join("state.json"))["step"].as_u64().unwrap(), steps);
    assert!(!out.join("session_open.json").exists());
    // A session that is killed (SIGKILL: no chance to save or write its sessions.jsonl
    // line) is recorded by the next one, up to the checkpoint that one resumes from.
    let mut child = crate::util::evalharness()
        .args(args)
        .args(["--resume", "-q"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let logged =
        |min: usize| std::fs::read_to_string(out.join("train_log.jsonl")).unwrap().lines().count() > min;
    let t0 = Instant::now();
    while !logged(steps as usize + 1) {
        assert!(t0.elapsed() < Duration::from_secs(300), "the resumed run never trained");
        std::thread::sleep(Duration::from_millis(50));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(out.join("session_open.json").is_file());
    expect_code(&run(&[&args[..], &["--resume", "--max-minutes", "0"]].concat()), 0);
    let sessions = read_json(&out.join("provenance.json"))["sessions"].clone();
    assert_eq!(sessions.as_array().map(Vec::len), Some(3), "{sessions}");
    assert!(sessions[1]["ended"].as_str().unwrap().starts_with("interrupted"), "{sessions}");
    // No checkpoint was due (every 1000 steps), so it is recorded from and to `steps`,
    // and the log's lines past the checkpoint were dropped when the run resumed.
    assert_eq!(
        (sessions[1]["from_step"].as_u64(), sessions[1]["to_step"].as_u64()),
        (Some(steps), Some(steps))
    );
    assert_eq!(sessions[2]["from_step"].as_u64(), Some(steps));
    assert!(sessions[2].get("ended").is_none());
    // A kill can land in the middle of a log line; the torn line is dropped with the
    // later ones (it once survived here, when a line was written token by token).
    let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), steps as usize, "{log}");
    assert!(!out.join("session_open.json").exists());
}

/// The same `train policy` command twice trains the same policy: its fresh weights and its
/// encoder's pose probe follow from `--seed` (until 2026-12-03 both were drawn unseeded, and
/// two runs' losses differed from the first logged step).
#[test]
fn the_same_policy_command_trains_the_same_policy() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let logs = ["a", "b"].map(|name| {
        let out = dir.path().join(name);
        let args = [
            "train",
            "policy",
            "--data",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--behaviour",
            "all",
            "--epochs",
            "2",
            "--batch",
            "20",
            "--encoder-width",
            "8",
            "--down-dims",
            "16,32",
            "--encoder-steps",
            "10",
        ];
        expect_code(&run(&args), 0);
        let log = std::fs::read_to_string(out.join(".train/log.jsonl")).unwrap();
        let mut rows: Vec<serde_json::Value> =
            log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        rows.iter_mut().for_each(|r| _ = r.as_object_mut().unwrap().remove("elapsed_s"));
        rows
    });
    // One pre-training line (at its last step, 10) and the policy's steps.
    assert!(logs[0].len() >= 3 && logs[0][0]["encoder_step"] == 10, "{:?}", logs[0]);
    assert_eq!(logs[0], logs[1]);
}
