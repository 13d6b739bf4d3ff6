//! `evalharness train autoencoder` and `train policy` on a tiny dataset: outputs, resume, bad input.

use std::path::Path;

use crate::util::{expect_code, read_json, run, scenario_variant};

/// 10 short explorer episodes (episode 9 is the held-out one).
fn tiny_dataset(dir: &Path, scenario: Option<&Path>) -> std::path::PathBuf {
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
}

#[test]
fn world_model_loss_variants_train_and_warm_start() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let ae = dir.path().join("ae");
    let (d, a) = (data.to_str().unwrap(), ae.to_str().unwrap());
    expect_code(&run(&["train", "autoencoder", "--data", d, "--out", a, "--steps", "1", "--batch", "2"]), 0);
    // The tiny dataset has 4-step episodes: one chunk of F = 4 needs 5 frames, so use a
    // longer one for two self-forcing chunks (8 targets).
    let long = dir.path().join("long.zarr");
    let args = ["collect", "--episodes", "10", "--max-steps", "12", "--mix", "explore=1", "--out"];
    expect_code(&run(&[&args[..], &[long.to_str().unwrap()]].concat()), 0);
    let wm_with = |out: &Path, channels: &str, extra: &[&str]| {
        let base = ["train", "world-model", "--data", long.to_str().unwrap(), "--autoencoder", a];
        let tiny = ["--base-channels", channels, "--contexts", "2", "--samples", "2", "--eval-every", "1"];
        run(&[&base[..], &["--out", out.to_str().unwrap()], &tiny[..], extra].concat())
    };
    let wm = |out: &Path, extra: &[&str]| wm_with(out, "16", extra);
    let first = dir.path().join("wm_token");
    let (stdout, _) = expect_code(
        &wm(&first, &["--steps", "2", "--field", "token", "--motion-weighting", "--self-forcing", "2"]),
        0,
    );
    assert!(stdout.contains("step 2/2"), "{stdout}");
    let cfg = read_json(&first.join("config.json"));
    assert_eq!(cfg["train"]["field"], "token");
    assert_eq!(cfg["train"]["chunks"], 2);
    assert_eq!(cfg["train"]["motion"]["lambda"], 12.0);
    assert!(
        read_json(&first.join("provenance.json"))["metrics"]["held_out_one_chunk_latent_mse"]
            .as_f64()
            .unwrap()
            .is_finite()
    );

    // A warm start reuses the first run's latent statistics.
    let second = dir.path().join("wm_warm");
    let from = first.to_str().unwrap();
    expect_code(&wm(&second, &["--steps", "1", "--init-from", from, "--warmup", "1"]), 0);
    assert_eq!(read_json(&second.join("config.json"))["model"]["latents"], cfg["model"]["latents"]);
    // ... and refuses a different U-Net.
    let third = dir.path().join("wm_wide");
    let (_, err) = expect_code(&wm_with(&third, "32", &["--steps", "1", "--init-from", from]), 2);
    assert!(err.contains("U-Net config differs"), "{err}");
    // Motion weighting and self-forcing belong to the drifting loss.
    let (_, err) = expect_code(&wm(&third, &["--objective", "mse", "--self-forcing", "2"]), 2);
    assert!(err.contains("--self-forcing"), "{err}");
    let (_, err) = expect_code(&wm(&third, &["--motion-weighting"]), 2);
    assert!(err.contains("--field token"), "{err}");
}
