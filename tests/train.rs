//! `evalharness train autoencoder`, `train world-model` and `train policy` on tiny datasets: outputs, resume, bad input.

use std::path::Path;

use serde_json::json;

use crate::util::{copy_dir, expect_code, read_json, run, scenario_variant};

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
    assert!(!logged(steps as usize) && !out.join("session_open.json").exists());
}

#[test]
fn world_model_loss_variants_train_and_warm_start() {
    let dir = tempfile::tempdir().unwrap();
    let data = tiny_dataset(dir.path(), None);
    let ae = dir.path().join("ae");
    let (d, a) = (data.to_str().unwrap(), ae.to_str().unwrap());
    expect_code(&run(&["train", "autoencoder", "--data", d, "--out", a, "--steps", "1", "--batch", "2"]), 0);
    // The tiny dataset has 4-step episodes: one chunk of F = 4 needs 5 frames, so use a
    // longer one for two self-forcing chunks (8 targets) and wm eval (4 + 60 frames).
    let long = dir.path().join("long.zarr");
    let args = ["collect", "--episodes", "10", "--max-steps", "70", "--mix", "explore=1", "--out"];
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
    // Its provenance nests the source's, snapshotted next to it.
    let prov = read_json(&second.join("provenance.json"));
    assert_eq!(prov["init_from"]["path"], from);
    assert_eq!(prov["init_from"]["provenance"]["steps"], 2);
    assert_eq!(read_json(&second.join("init_from_provenance.json"))["steps"], 2);
    assert_eq!(read_json(&first.join("provenance.json"))["init_from"], serde_json::Value::Null);
    // The commit is the one the binary was built from (this checkout's HEAD).
    let head = std::process::Command::new("git").args(["rev-parse", "HEAD"]).output().unwrap();
    let commit = prov["commit"].as_str().unwrap().to_string();
    match String::from_utf8(head.stdout).unwrap().trim() {
        "" => assert_eq!(commit, "unknown"),
        head => assert!(commit == head || commit == format!("{head}+dirty"), "{commit} vs {head}"),
    }
    // Action accentuation (spec §3) on a warm start: the α MLP is added with zero output,
    // the true current frame joins each token problem's negatives, and the inference α is
    // written to the model config; α < 1, or α for a model without accentuation, is refused.
    let acc = dir.path().join("wm_accent");
    let accent = ["--steps", "1", "--init-from", from, "--warmup", "1", "--field", "token", "--accentuation"];
    expect_code(&wm(&acc, &[&accent[..], &["--alpha", "3"]].concat()), 0);
    let acc_cfg = read_json(&acc.join("config.json"));
    assert_eq!(acc_cfg["model"]["unet"]["accentuation"], true);
    assert_eq!(acc_cfg["model"]["alpha"], 3.0);
    assert_eq!(cfg["model"]["alpha"], serde_json::Value::Null);
    let (_, err) = expect_code(&wm(&acc, &[&accent[..], &["--alpha", "0.5", "--force"]].concat()), 2);
    assert!(err.contains("--alpha"), "{err}");
    let (_, err) = expect_code(&wm(&dir.path().join("wm_alpha"), &["--steps", "1", "--alpha", "2"]), 2);
    assert!(err.contains("--alpha"), "{err}");
    // `wm export --alpha` ships the α chosen on validation episodes (recorded in the export
    // entry); for a model without accentuation it is refused.
    let acc_ship = dir.path().join("ship_accent");
    let exp = ["wm", "export", "--from", acc.to_str().unwrap(), "--out", acc_ship.to_str().unwrap()];
    expect_code(&run(&[&exp[..], &["--alpha", "4"]].concat()), 0);
    assert_eq!(read_json(&acc_ship.join("config.json"))["model"]["alpha"], 4.0);
    assert_eq!(read_json(&acc_ship.join("provenance.json"))["exported"][0]["alpha"], 4.0);
    let plain_ship = dir.path().join("ship_plain");
    let plain = ["wm", "export", "--from", from, "--out", plain_ship.to_str().unwrap()];
    let (_, err) = expect_code(&run(&[&plain[..], &["--alpha", "2"]].concat()), 2);
    assert!(
        err.contains("--alpha 2") && err.contains("not trained with --accentuation") && !plain_ship.exists(),
        "{err}"
    );
    // A warm start may add action maps and the anchor (zero-initialised input channels);
    // the run resumes with them, and a run without maps cannot start from it.
    let maps = dir.path().join("wm_maps");
    // (With context-noise augmentation, recorded in the run's config.)
    let noisy = ["--context-noise", "0.25"];
    expect_code(
        &wm(
            &maps,
            &[
                &["--steps", "1", "--init-from", from, "--warmup", "1", "--action-maps", "--anchor"],
                &noisy[..],
            ]
            .concat(),
        ),
        0,
    );
    assert_eq!(read_json(&maps.join("config.json"))["model"]["unet"]["action_maps"], true);
    assert_eq!(read_json(&maps.join("config.json"))["model"]["unet"]["anchor"], true);
    assert_eq!(cfg["model"]["unet"]["anchor"], serde_json::Value::Null);
    assert_eq!(read_json(&maps.join("config.json"))["train"]["context_noise"], 0.25);
    assert_eq!(cfg["train"]["context_noise"], 0.0);
    assert_eq!(cfg["model"]["unet"]["action_maps"], serde_json::Value::Null);
    expect_code(&wm(&maps, &["--steps", "2", "--resume", "--ema-decay", "0.99"]), 0);
    assert_eq!(read_json(&maps.join("config.json"))["train"]["ema_decay"], 0.99);
    let (_, err) = expect_code(&wm(&maps, &["--steps", "3", "--resume", "--ema-decay", "1.5"]), 2);
    assert!(err.contains("--ema-decay"), "{err}");
    // Model and loss flags that contradict the saved run are refused, not ignored
    // (the ones equal to it, from `wm`'s own arguments, are accepted above).
    let resume =
        ["--steps", "3", "--resume", "--self-forcing", "3", "--warmup", "1", "--context-noise", "0.5"];
    let (_, err) = expect_code(&wm_with(&maps, "24", &resume), 2);
    assert!(err.contains("--self-forcing (saved: 1)"), "{err}");
    assert!(err.contains("--context-noise (saved: 0.25)"), "{err}");
    assert!(err.contains("--base-channels (saved: 16)"), "{err}");
    assert!(!err.contains("--warmup"), "{err}");
    assert_eq!(read_json(&maps.join("state.json"))["step"], 2);
    // A bad --init-from is refused before --force clears the output, which survives.
    let missing = dir.path().join("no_such_run");
    let (_, err) =
        expect_code(&wm(&maps, &["--steps", "1", "--force", "--init-from", missing.to_str().unwrap()]), 2);
    assert!(err.contains("--init-from") && err.contains("no_such_run"), "{err}");
    let (_, err) =
        expect_code(&wm(&maps, &["--steps", "1", "--force", "--init-from", maps.to_str().unwrap()]), 2);
    assert!(err.contains("is the output folder itself"), "{err}");
    assert_eq!(read_json(&maps.join("state.json"))["step"], 2);
    let back = dir.path().join("wm_back");
    let (_, err) = expect_code(&wm(&back, &["--steps", "1", "--init-from", maps.to_str().unwrap()]), 2);
    assert!(err.contains("U-Net config differs"), "{err}");
    // ... and refuses a different U-Net.
    let third = dir.path().join("wm_wide");
    let (_, err) = expect_code(&wm_with(&third, "32", &["--steps", "1", "--init-from", from]), 2);
    assert!(err.contains("U-Net config differs"), "{err}");
    // The x0-predicting diffusion baseline starts from a one-pass model (its timestep
    // embedding added with zero output); `--prediction` belongs to diffusion, and a
    // resume that names the other parameterisation is refused.
    let diff = dir.path().join("wm_diff");
    let m = maps.to_str().unwrap();
    let x0 = [
        "--objective",
        "diffusion",
        "--prediction",
        "x0",
        "--sample-steps",
        "2",
        "--action-maps",
        "--anchor",
    ];
    expect_code(&wm(&diff, &[&x0[..], &["--steps", "1", "--init-from", m, "--warmup", "1"]].concat()), 0);
    let model = &read_json(&diff.join("config.json"))["model"];
    assert_eq!((&model["prediction"], &model["unet"]["timestep_embedding"]), (&json!("x0"), &json!(true)));
    assert_eq!(read_json(&maps.join("config.json"))["model"].get("prediction"), None);
    let ev = dir.path().join("eval_diff");
    let args = ["wm", "eval", "--world-model", diff.to_str().unwrap(), "--data", long.to_str().unwrap()];
    let few = ["--episodes", "1", "--full-episodes", "0", "--out", ev.to_str().unwrap()];
    expect_code(&run(&[&args[..], &few[..]].concat()), 0);
    let models = read_json(&ev.join("eval.json"))["models"].clone();
    assert_eq!(models[0]["objective"], "diffusion");
    assert!(models[0]["ssim"].as_f64().unwrap().is_finite(), "{models}");
    // `wm export` makes a folder to ship: EMA weights, logs, provenance with an
    // `exported` entry, the autoencoder path rewritten for the new depth; no resume state.
    let shipped = dir.path().join("ship").join("pusht").join("wm_diffusion");
    let export = |from: &Path| {
        let args = ["wm", "export", "--from", from.to_str().unwrap(), "--out", shipped.to_str().unwrap()];
        run(&args)
    };
    expect_code(&export(&diff), 0);
    let cfg = read_json(&shipped.join("config.json"));
    let ae_rel = cfg["model"]["autoencoder"].as_str().unwrap();
    assert_eq!(ae_rel, "../../../ae");
    assert_eq!(shipped.join(ae_rel).canonicalize().unwrap(), ae.canonicalize().unwrap());
    assert_eq!(cfg["model"]["prediction"], "x0");
    let prov = read_json(&shipped.join("provenance.json"));
    assert_eq!(prov["exported"][0]["from"], diff.to_str().unwrap());
    assert_eq!(prov["steps"], 1);
    assert!(shipped.join("ema.bpk").is_file() && !shipped.join("optimizer.bpk").exists());
    let (_, err) = expect_code(&export(&diff), 2);
    assert!(err.contains("already exists"), "{err}");
    // A narrower decoder on the same encoder's latents (`train autoencoder
    // --encoder-from`) replaces the run's decoder in an export; an autoencoder with
    // another encoder is refused, since the world model's latents would not match.
    let narrow = dir.path().join("ae_narrow");
    let n = narrow.to_str().unwrap();
    let dec = ["train", "autoencoder", "--data", d, "--out", n, "--steps", "1", "--batch", "2"];
    expect_code(&run(&[&dec[..], &["--encoder-from", a, "--decoder-channels", "8,16,32,32"]].concat()), 0);
    let prov = read_json(&narrow.join("provenance.json"));
    assert_eq!(prov["decoder_channels"], json!([8, 16, 32, 32]));
    assert_eq!(prov["encoder_from"]["path"], a);
    let (_, err) =
        expect_code(&run(&[&dec[..], &["--resume", "--decoder-channels", "16,32,64,64"]].concat()), 2);
    assert!(err.contains("--decoder-channels (saved: [8,16,32,32])"), "{err}");
    let bad = dir.path().join("ae_bad");
    let (_, err) = expect_code(
        &run(&[
            "train",
            "autoencoder",
            "--data",
            d,
            "--out",
            bad.to_str().unwrap(),
            "--decoder-channels",
            "8,16,32",
        ]),
        2,
    );
    assert!(err.contains("--decoder-channels") && err.contains("four multiples of 8"), "{err}");
    let swapped = dir.path().join("ship").join("wm_narrow");
    let args = ["wm", "export", "--from", diff.to_str().unwrap(), "--autoencoder", n];
    expect_code(&run(&[&args[..], &["--out", swapped.to_str().unwrap()]].concat()), 0);
    let cfg = read_json(&swapped.join("config.json"));
    assert_eq!(cfg["model"]["autoencoder"], "../../ae_narrow");
    assert_eq!(read_json(&swapped.join("provenance.json"))["autoencoder_replaced"]["now"], n);
    let ev = dir.path().join("eval_narrow");
    let args = ["wm", "eval", "--world-model", swapped.to_str().unwrap(), "--data", long.to_str().unwrap()];
    let few = ["--episodes", "1", "--full-episodes", "0", "--out", ev.to_str().unwrap()];
    expect_code(&run(&[&args[..], &few[..]].concat()), 0);
    // `--windows random` (the authors' protocol): windows drawn over every position
    // of the held-out episodes (index % 10 == 9), recorded with their start frames.
    let ev = dir.path().join("eval_random");
    let random = ["--episodes", "3", "--full-episodes", "0", "--windows", "random", "--seed", "5"];
    expect_code(&run(&[&args[..], &random[..], &["--out", ev.to_str().unwrap()]].concat()), 0);
    let eval = read_json(&ev.join("eval.json"));
    assert_eq!((&eval["windows_64"], &eval["videos_64"]), (&json!("random"), &json!(3)));
    let episodes: Vec<u64> =
        eval["episodes_64"].as_array().unwrap().iter().map(|e| e.as_u64().unwrap()).collect();
    assert!(episodes.iter().all(|e| e % 10 == 9), "{episodes:?}");
    assert_eq!(eval["starts_64"].as_array().unwrap().len(), 3);
    // Each row's SSIM interval holds its SSIM.
    for m in eval["models"].as_array().unwrap() {
        let (ssim, ci) = (m["ssim"].as_f64().unwrap(), m["ssim_ci"].as_array().unwrap());
        assert!(ci[0].as_f64().unwrap() <= ssim + 1e-12 && ssim <= ci[1].as_f64().unwrap() + 1e-12, "{m}");
    }
    // Every video falls in one block-motion bin, each with a mean SSIM per row.
    let bins = eval["ssim_by_block_motion"]["bins"].as_array().unwrap().clone();
    assert_eq!(bins.iter().map(|b| b["videos"].as_u64().unwrap()).sum::<u64>(), 3, "{bins:?}");
    assert!(
        bins.iter().filter(|b| b["videos"] != 0).all(|b| b["ssim"].as_array().unwrap().len() >= 2),
        "{bins:?}"
    );
    // `--start` re-runs one of those videos; step 0 (episode 0, trained on) is refused.
    let start = eval["starts_64"][1].as_u64().unwrap().to_string();
    let ev = dir.path().join("eval_start");
    expect_code(
        &run(&[&args[..], &["--start", &start, "--full-episodes", "0", "--out", ev.to_str().unwrap()]]
            .concat()),
        0,
    );
    let eval = read_json(&ev.join("eval.json"));
    assert_eq!(
        (&eval["windows_64"], &eval["starts_64"][0]),
        (&json!("given (--start)"), &json!(start.parse::<u64>().unwrap()))
    );
    let (_, err) = expect_code(
        &run(&[&args[..], &["--start", "0", "--out", ev.to_str().unwrap(), "--force"]].concat()),
        2,
    );
    assert!(err.contains("--start 0: no held-out episode holds step 0"), "{err}");
    // A model whose output goes non-finite (a latent scale of 1e-38 blows the encoded
    // history up to ~1e37, and the U-Net's GroupNorm overflows) stops `wm eval` with
    // exit 2, naming the model and the frames, and leaves no results behind.
    let blown = dir.path().join("ship").join("wm_blown");
    copy_dir(&swapped, &blown);
    let mut cfg = read_json(&blown.join("config.json"));
    cfg["model"]["latents"]["std"][0] = json!(1e-38);
    std::fs::write(blown.join("config.json"), cfg.to_string()).unwrap();
    let ev = dir.path().join("eval_blown");
    let args = ["wm", "eval", "--world-model", blown.to_str().unwrap(), "--data", long.to_str().unwrap()];
    let few = ["--episodes", "1", "--full-episodes", "0", "--out", ev.to_str().unwrap()];
    let (_, err) = expect_code(&run(&[&args[..], &few[..]].concat()), 2);
    assert!(
        err.contains("world model wm_blown") && err.contains("non-finite latents in generated frames 0..4"),
        "{err}"
    );
    assert!(!ev.exists(), "a failed evaluation left {}", ev.display());
    let other = dir.path().join("ae_other");
    let o = other.to_str().unwrap();
    expect_code(
        &run(&[
            "train",
            "autoencoder",
            "--data",
            d,
            "--out",
            o,
            "--steps",
            "1",
            "--batch",
            "2",
            "--seed",
            "1",
        ]),
        0,
    );
    let args = ["wm", "export", "--from", diff.to_str().unwrap(), "--autoencoder", o];
    let (_, err) =
        expect_code(&run(&[&args[..], &["--out", dir.path().join("x2").to_str().unwrap()]].concat()), 2);
    assert!(err.contains("its encoder differs") && err.contains("--encoder-from"), "{err}");
    // A run whose checkpoint is ahead of its provenance (a session killed after a
    // checkpoint) is not exported under the older provenance.
    let state = std::fs::read_to_string(diff.join("state.json")).unwrap();
    std::fs::write(diff.join("state.json"), r#"{"step":7,"elapsed_s":1.0}"#).unwrap();
    let elsewhere = dir.path().join("ship_stale");
    let (_, err) = expect_code(
        &run(&["wm", "export", "--from", diff.to_str().unwrap(), "--out", elsewhere.to_str().unwrap()]),
        2,
    );
    assert!(err.contains("records 1 steps") && err.contains("at step 7"), "{err}");
    assert!(err.contains("--resume --max-minutes 0") && !elsewhere.exists(), "{err}");
    std::fs::write(diff.join("state.json"), state).unwrap();
    let (_, err) =
        expect_code(&run(&["wm", "export", "--from", a, "--out", dir.path().join("x").to_str().unwrap()]), 2);
    assert!(err.contains(&format!("--from {a}")) && err.contains("config.json"), "{err}");
    let (_, err) = expect_code(&wm(&diff, &["--steps", "2", "--resume", "--prediction", "v"]), 2);
    assert!(err.contains("--prediction (saved: \"x0\")"), "{err}");
    let (_, err) = expect_code(&wm(&third, &["--prediction", "x0"]), 2);
    assert!(err.contains("--prediction") && err.contains("--objective diffusion"), "{err}");
    // Motion weighting and self-forcing belong to the drifting loss.
    let (_, err) = expect_code(&wm(&third, &["--objective", "mse", "--self-forcing", "2"]), 2);
    assert!(err.contains("--self-forcing"), "{err}");
    let (_, err) = expect_code(&wm(&third, &["--context-noise=-0.5"]), 2);
    assert!(err.contains("--context-noise"), "{err}");
    let (_, err) = expect_code(&wm(&third, &["--motion-weighting"]), 2);
    assert!(err.contains("--field token"), "{err}");
}

#[test]
fn pixel_space_world_model_trains_resumes_and_rolls_out() {
    let dir = tempfile::tempdir().unwrap();
    // 70-step episodes: wm eval's 64-frame rollouts need 4 context frames + 60.
    let data = dir.path().join("long.zarr");
    let d = data.to_str().unwrap();
    let collect = ["collect", "--episodes", "10", "--max-steps", "70", "--mix", "explore=1", "--out", d];
    expect_code(&run(&collect), 0);
    let out = dir.path().join("pix");
    let o = out.to_str().unwrap();
    // The paper's family with a narrow U-Net (base 32 instead of 96) to stay fast on a CPU.
    let args = ["train", "world-model", "--config", "pusht-pixel", "--data", d, "--out", o];
    let tiny = ["--base-channels", "32", "--contexts", "1", "--samples", "2", "--eval-windows", "2"];
    let (stdout, _) = expect_code(&run(&[&args[..], &tiny[..], &["--steps", "1"]].concat()), 0);
    assert!(stdout.contains("step 1/1"), "{stdout}");
    let cfg = read_json(&out.join("config.json"));
    assert_eq!(cfg["model"]["autoencoder"], serde_json::Value::Null);
    assert_eq!(cfg["model"]["unet"]["frame_channels"], 3);
    assert_eq!(cfg["model"]["unet"]["channel_mult"], serde_json::json!([1, 1, 1, 1]));
    assert_eq!(cfg["model"]["latents"]["size"], 96);
    assert!(read_json(&out.join("provenance.json"))["what"].as_str().unwrap().ends_with("on pixels"));

    // Resuming keeps the pixel config; an autoencoder cannot be slipped in.
    let resume = ["--resume", "--steps", "2"];
    expect_code(&run(&[&args[..], &tiny[..], &resume[..]].concat()), 0);
    assert_eq!(read_json(&out.join("state.json"))["step"], 2);
    let (_, err) = expect_code(&run(&[&args[..], &resume[..], &["--autoencoder", d]].concat()), 2);
    assert!(err.contains("pixel-space model, it takes no --autoencoder"), "{err}");
    // The two families need (or refuse) an autoencoder.
    let fresh = dir.path().join("other");
    let f = fresh.to_str().unwrap();
    let (_, err) = expect_code(&run(&["train", "world-model", "--data", d, "--out", f]), 2);
    assert!(err.contains("pass --autoencoder DIR"), "{err}");
    let (_, err) = expect_code(&run(&[&args[..6], &["--out", f, "--autoencoder", d]].concat()), 2);
    assert!(err.contains("takes no --autoencoder"), "{err}");

    // A pixel model rolls out like a latent one: wm eval on one held-out episode.
    let ev = dir.path().join("eval");
    let eval = ["wm", "eval", "--world-model", o, "--data", d, "--episodes", "1", "--full-episodes", "0"];
    let eval = [&eval[..], &["--out", ev.to_str().unwrap()]].concat();
    expect_code(&run(&eval), 0);
    let e = read_json(&ev.join("eval.json"));
    assert_eq!(e["models"][0]["frames"], 60);
    assert!(e["models"][0]["psnr"].as_f64().unwrap().is_finite());
    // A GPU request on a CPU-only build is an error that says how to build one.
    if cfg!(not(feature = "cuda")) {
        let out = crate::util::evalharness().args(&eval).env("EVALHARNESS_DEVICE", "cuda").output().unwrap();
        let (_, err) = expect_code(&out, 2);
        assert!(err.contains("EVALHARNESS_DEVICE=cuda") && err.contains("--features cuda"), "{err}");
    }
}
