//! `evalharness train world-model` on tiny datasets: the loss variants, warm starts,
//! the pixel-space model, resume and the flags it refuses.

use std::path::Path;

use serde_json::json;

use crate::train::tiny_dataset;
use crate::util::{copy_dir, evalharness, expect_code, read_json, run};

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
    // The same command twice trains the same model: the fresh weights follow from --seed
    // (they once came from an unseeded draw, and two runs' first losses differed).
    let logs = ["wm_a", "wm_b"].map(|name| {
        let out = dir.path().join(name);
        expect_code(&wm(&out, &["--steps", "2", "--objective", "mse"]), 0);
        let log = std::fs::read_to_string(out.join("train_log.jsonl")).unwrap();
        let mut rows: Vec<serde_json::Value> =
            log.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
        rows.iter_mut().for_each(|r| _ = r.as_object_mut().unwrap().remove("elapsed_s"));
        rows
    });
    assert_eq!(logs[0], logs[1]);
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
    let sampling = read_json(&ev.join("eval.json"))["sampling"].clone();
    assert_eq!(sampling[0]["noise_scale"], 1.0, "{sampling}");
    // Its U-Net has no α input, so no α is in effect.
    assert_eq!(sampling[0]["alpha"], serde_json::Value::Null, "{sampling}");
    // A diffusion model's noise starts its DDIM sampling: it takes no temperature.
    let cold = ["--noise-scale", "0.5", "--force"];
    let (_, err) = expect_code(&run(&[&args[..], &few[..], &cold[..]].concat()), 2);
    assert!(err.contains("--noise-scale: a diffusion model's noise starts its DDIM sampling"), "{err}");
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
    // Given relative to the working directory (`ae_narrow`), the replacement is recorded
    // relative to the exported folder, as the config's path (it was recorded as given).
    let swapped = dir.path().join("ship").join("wm_narrow");
    let args = ["wm", "export", "--from", diff.to_str().unwrap(), "--autoencoder", "ae_narrow"];
    let code =
        evalharness().current_dir(dir.path()).args(args).args(["--out", swapped.to_str().unwrap()]).output();
    expect_code(&code.expect("evalharness runs"), 0);
    let cfg = read_json(&swapped.join("config.json"));
    assert_eq!(cfg["model"]["autoencoder"], "../../ae_narrow");
    assert_eq!(read_json(&swapped.join("provenance.json"))["autoencoder_replaced"]["now"], "../../ae_narrow");
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

    // A width the U-Net cannot be built with is an error naming the setting, not a panic
    // (burn's GroupNorm asserted at 1951e7c).
    let narrow = dir.path().join("narrow");
    let (_, err) = expect_code(
        &run(&[&args[..6], &["--out", narrow.to_str().unwrap(), "--base-channels", "16"]].concat()),
        2,
    );
    assert!(err.contains("--base-channels 16") && err.contains("groups (32)"), "{err}");

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
