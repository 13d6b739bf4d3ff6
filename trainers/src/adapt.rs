//! `evalharness train adapt`: a task's models adapted to another rendering of its frames.
//!
//! Retraining a task's policies, autoencoder, world model and judge on cheaper frames is
//! hours of CPU per task, and gives other models. What reads frames, though, is only the
//! policies' frame encoder (frozen and shared by a pre-trained policy set's checkpoints) and
//! the autoencoder's encoder: both are distilled ([`policies::adapt`]) to read the new
//! rendering as they read the old, on the same episodes rendered both ways (`--from`,
//! `--to`). The policies' U-Nets, the autoencoder's decoder, the world model and the judge
//! (which reads decoded frames) are kept as they are. Every 10th episode is held out and
//! the relative feature error on it, before and after, is reported and recorded in
//! `adaptation.json` at the folder's root and in each adapted checkpoint.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::tensor::{Device, Tensor};
use policies::adapt::{Distil, Pairs, distil, paired, relative_errors};
use policies::adapt_decision::{Decisions, decision_errors};
use policies::data::Demos;
use policies::diffusion::{DiffusionConfig, DiffusionNet};
use policies::dir::{
    PolicyFile, checkpoint_dirs, diffusion_config, diffusion_weights, read_policy_file, write_policy,
};
use policies::net::ObsEncoder;
use runner::command::write_json;
use serde::{Deserialize, Serialize};
use world_model::autoencoder::Autoencoder;
use world_model::model::WorldModelConfig;
use world_model::train_ae::load_autoencoder;

use crate::args::TrainAdaptArgs;
use crate::common::{data_provenance, dataset_task, prepare_out};
use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use harness::provenance::FramesUsed;

/// Which episodes are held out of the distillation (and measure it).
const HELD_OUT: &str = "episodes with index % 10 == 9";

/// One distilled encoder: the relative squared error of its output against the original
/// encoder's output on the old rendering, on the held-out steps, each rendering, before and after.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Distilled {
    /// What it encodes for: the policy checkpoints sharing it, or `autoencoder`.
    pub used_by: Vec<String>,
    /// Before: (old rendering, new rendering); the old encoder on the old frames is 0.
    pub before: (f64, f64),
    /// After distillation.
    pub after: (f64, f64),
    /// For a policy encoder: the mean squared difference of its checkpoints' noise
    /// predictions from the original's on the old frames ([`decision_errors`]), on the
    /// held-out steps, each rendering, before and after (absent for the autoencoder and in
    /// folders adapted by a binary before cb10675, such as the shipped Lift folder).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decisions: Option<((f64, f64), (f64, f64))>,
}

/// `adaptation.json`: how a model folder was adapted to a rendering.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Adaptation {
    /// The command line.
    pub command: String,
    /// The commit of the binary.
    pub commit: String,
    /// The model folder adapted.
    pub models: String,
    /// The episodes in the old rendering.
    pub from: FramesUsed,
    /// The same episodes in the new rendering.
    pub to: FramesUsed,
    /// Which episodes measured the errors instead of training.
    pub held_out: String,
    /// Distillation settings of the policies' encoders.
    pub policy_encoders: Distil,
    /// Distillation settings of the autoencoder's encoder.
    pub autoencoder_encoder: Distil,
    /// Each distinct encoder distilled.
    pub distilled: Vec<Distilled>,
    /// Training seconds.
    pub elapsed_s: f64,
}

fn obs_encoder(m: &ObsEncoder, x: Tensor<4>) -> Tensor<2> {
    m.forward(x) // [n, feature_dim]
}

fn ae_encoder(m: &Autoencoder, x: Tensor<4>) -> Tensor<2> {
    let z = m.encode(x); // [n, C, 12, 12]
    let [n, c, h, w] = z.dims();
    z.reshape([n, c * h * w])
}

/// Whether two encoders are one, up to the rounding of the checkpoints' f16 weights and of the
/// moving average that exported them: outputs on a fixed frame-like input within 1e-3 of the
/// largest (a policy set trained on a frozen encoder exports it once per epoch, bits apart).
fn same_encoder(a: &ObsEncoder, b: &ObsEncoder, size: usize, device: &Device) -> bool {
    let x = nn::frames::probe_frames(1, size, device); // [1, 3, size, size]
    let out = |e: &ObsEncoder| {
        obs_encoder(e, x.clone()).into_data().convert::<f32>().try_into_vec::<f32>().unwrap_or_default()
    };
    let (ya, yb) = (out(a), out(b));
    let scale = ya.iter().fold(1.0_f32, |m, v| m.max(v.abs()));
    ya.len() == yb.len() && ya.iter().zip(&yb).all(|(p, q)| (p - q).abs() <= 1e-3 * scale)
}

/// Copies the plain files of `from` (not its sub-folders, hidden files or those named in
/// `skip`) into `to`.
fn copy_files(from: &Path, to: &Path, skip: &[&str]) -> Result<()> {
    std::fs::create_dir_all(to).with_context(|| format!("creating {}", to.display()))?;
    for e in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let p = e.with_context(|| format!("reading {}", from.display()))?.path();
        let name = p.file_name().and_then(|n| n.to_str());
        let left_out = name.is_none_or(|n| n.starts_with('.') || skip.contains(&n));
        if p.is_file() && !left_out {
            let dest = to.join(p.file_name().unwrap_or_default());
            std::fs::copy(&p, &dest)
                .with_context(|| format!("copying {} to {}", p.display(), dest.display()))?;
        }
    }
    Ok(())
}

/// A policy checkpoint: its folder, file, networks and configuration.
type Policy = (PathBuf, PolicyFile, DiffusionNet, DiffusionConfig);

/// The policy checkpoints of `dir`, each with its file and networks.
fn load_policies(dir: &Path, device: &Device) -> Result<Vec<Policy>> {
    let mut out = Vec::new();
    for d in checkpoint_dirs(dir)? {
        let file = read_policy_file(&d)?;
        if file.kind != "diffusion" {
            refuse!(
                "--models: {} is a \"{}\" checkpoint; only the project's diffusion policies are adapted",
                d.display(),
                file.kind
            );
        }
        let cfg = diffusion_config(&d, &file)?;
        let net = diffusion_weights(&d, &cfg, device)?;
        out.push((d, file, net, cfg));
    }
    Ok(out)
}

/// Refuses a `--models` folder without policies or autoencoder, or whose world model reads
/// its autoencoder from elsewhere than beside it (its copy would not read the adapted one).
fn check_models(a: &TrainAdaptArgs) -> Result<()> {
    for part in ["policies", "autoencoder"] {
        if !a.models.join(part).is_dir() {
            refuse!("--models {}: no {part} folder", a.models.display());
        }
    }
    let wm_dir = a.models.join("world_model");
    if wm_dir.is_dir() {
        let cfg = WorldModelConfig::read(&wm_dir)?;
        if cfg.autoencoder.as_deref() != Some(Path::new("../autoencoder")) {
            refuse!(
                "--models: {} reads its autoencoder from {:?}, not ../autoencoder, so its copy could not read the adapted one",
                wm_dir.display(),
                cfg.autoencoder
            );
        }
    }
    Ok(())
}

/// The two renderings of `--from` and `--to` at `size`, checked to pair up step by step, and
/// their steps split into training and held-out ones ([`HELD_OUT`]).
fn load_pairs(a: &TrainAdaptArgs, size: usize) -> Result<(Demos, Demos, Vec<usize>, Vec<usize>)> {
    let (task, task_to) = (dataset_task(&a.from)?, dataset_task(&a.to)?);
    if task.name() != task_to.name() {
        refuse!("--from is a {} dataset and --to a {} one", task.name(), task_to.name());
    }
    let from = Demos::load(&a.from, task.as_ref(), None, None, size)?;
    let to = Demos::load(&a.to, task.as_ref(), None, None, size)?;
    if let Some(why) = paired(&from, &to) {
        refuse!(
            "--from {} and --to {} do not hold the same episodes: {why}",
            a.from.display(),
            a.to.display()
        );
    }
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (e, r) in from.episodes.iter().enumerate() {
        if e % 10 == 9 { test.extend(r.clone()) } else { train.extend(r.clone()) }
    }
    if test.is_empty() {
        refuse!(
            "--from {}: {} episodes hold none out ({HELD_OUT}); collect at least 10",
            a.from.display(),
            from.episodes.len()
        );
    }
    Ok((from, to, train, test))
}

/// A progress bar that also logs every 100th step, for runs whose stderr is not a terminal.
fn follow<'a>(bar: &'a runner::progress::ProgressBar, what: &'a str) -> impl FnMut(u64, f64) + 'a {
    move |s, l| {
        bar.set_position(s);
        bar.set_message(format!("loss {l:.5}"));
        if s % 100 == 0 {
            tracing::info!(step = s, loss = l, "distilling {what}");
        }
    }
}

/// The U-Nets of `users` among `policies` that share the first one's windows (observed steps,
/// horizon, diffusion schedule): what the decision error is measured with.
fn decisions<'a>(policies: &'a [Policy], users: &[usize]) -> Decisions<'a> {
    let first = &policies[users[0]].3;
    let same = |c: &DiffusionConfig| {
        (c.net.obs_horizon, c.horizon, c.train_steps)
            == (first.net.obs_horizon, first.horizon, first.train_steps)
    };
    Decisions {
        policies: users
            .iter()
            .map(|&i| &policies[i])
            .filter(|p| same(&p.3))
            .map(|p| (&p.2.unet, &p.1.normalisation))
            .collect(),
        obs_horizon: first.net.obs_horizon,
        horizon: first.horizon,
        train_steps: first.train_steps,
    }
}

/// Distils each distinct frame encoder of `policies` (checkpoints sharing one, in checkpoint
/// order, are distilled once): the student of each checkpoint, and what each distillation did,
/// in features and in the sharing checkpoints' decisions.
fn distil_policies(
    policies: &[Policy],
    (fit, check): (&Pairs, &Pairs),
    d: Distil,
    device: &Device,
    quiet: bool,
) -> Result<(Vec<ObsEncoder>, Vec<Distilled>)> {
    let size = fit.from.size;
    let mut encoders: Vec<(ObsEncoder, Vec<usize>)> = Vec::new();
    for (i, p) in policies.iter().enumerate() {
        match encoders.iter_mut().find(|(e, _)| same_encoder(e, &p.2.encoder, size, device)) {
            Some((_, users)) => users.push(i),
            None => encoders.push((p.2.encoder.clone(), vec![i])),
        }
    }
    let (mut students, mut distilled) = (vec![None; policies.len()], Vec::new());
    for (k, (teacher, users)) in encoders.iter().enumerate() {
        let what = format!("policy encoder {}/{}", k + 1, encoders.len());
        let bar = runner::progress::bar(d.steps, &what, quiet);
        let refused = |e: String| crate::TrainError::Refused(format!("{what}: {e}"));
        let student =
            distil(teacher, obs_encoder, fit, d, device, &mut follow(&bar, &what)).map_err(refused)?;
        bar.finish_and_clear();
        let errors = relative_errors(teacher, &[teacher, &student], obs_encoder, check, device);
        let (before, after) = (errors[0], errors[1]);
        let e = decision_errors(teacher, &[teacher, &student], check, &decisions(policies, users), device);
        let decisions = Some((e[0], e[1]));
        let used_by = users.iter().map(|&i| policies::dir::checkpoint_name(&policies[i].0)).collect();
        distilled.push(Distilled { used_by, before, after, decisions });
        for &i in users {
            students[i] = Some(student.clone());
        }
    }
    Ok((students.into_iter().flatten().collect(), distilled))
}

/// Distils the autoencoder in `dir`'s encoder (its decoder is not reached by the loss).
fn distil_autoencoder(
    dir: &Path,
    (fit, check): (&Pairs, &Pairs),
    d: Distil,
    device: &Device,
    quiet: bool,
) -> Result<(Autoencoder, Distilled)> {
    let (ae, _) = load_autoencoder(dir, device)?;
    let what = "the autoencoder's encoder";
    let bar = runner::progress::bar(d.steps, what, quiet);
    let student = distil(&ae, ae_encoder, fit, d, device, &mut follow(&bar, what))
        .map_err(|e| crate::TrainError::Refused(format!("{what}: {e}")))?;
    bar.finish_and_clear();
    let errors = relative_errors(&ae, &[&ae, &student], ae_encoder, check, device);
    let (before, after) = (errors[0], errors[1]);
    Ok((student, Distilled { used_by: vec!["autoencoder".into()], before, after, decisions: None }))
}

/// `evalharness train adapt`.
pub fn run(a: &TrainAdaptArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    check_models(a)?;
    let inputs = [("--models", a.models.as_path()), ("--from", &a.from), ("--to", &a.to)];
    let out_dir = prepare_out(&a.out, false, a.force, "adaptation.json", &inputs)?;
    let device = nn::device::selected()?;
    let policies = load_policies(&a.models.join("policies"), &device)?;
    let size = policies.first().map_or(96, |p| p.3.net.image_size);
    if let Some((d, _, _, other)) = policies.iter().find(|p| p.3.net.image_size != size) {
        refuse!("--models: {} reads {}² frames, the others {size}²", d.display(), other.net.image_size);
    }
    let (from, to, train, test) = load_pairs(a, size)?;
    let fit = Pairs { from: &from, to: &to, steps: &train };
    let check = Pairs { from: &from, to: &to, steps: &test };
    let started = std::time::Instant::now();
    let d_pol = Distil { steps: a.steps, batch: a.batch, lr: a.lr, seed: a.seed };
    let d_ae =
        Distil { steps: a.ae_steps, batch: a.batch.div_ceil(2), lr: a.lr, seed: a.seed.wrapping_add(1) };
    let (students, mut distilled) = distil_policies(&policies, (&fit, &check), d_pol, &device, inv.quiet)?;
    let (ae, d) =
        distil_autoencoder(&a.models.join("autoencoder"), (&fit, &check), d_ae, &device, inv.quiet)?;
    distilled.push(d);
    let adaptation = Adaptation {
        command: inv.command_line.join(" "),
        commit: inv.commit.clone(),
        models: a.models.display().to_string(),
        from: data_provenance(&a.from, from.episodes.len(), from.len())?,
        to: data_provenance(&a.to, to.episodes.len(), to.len())?,
        held_out: HELD_OUT.into(),
        policy_encoders: d_pol,
        autoencoder_encoder: d_ae,
        distilled,
        elapsed_s: started.elapsed().as_secs_f64(),
    };
    write_folder(a, &policies, students, &ae, &adaptation)?;
    for d in &adaptation.distilled {
        let who = if d.used_by == ["autoencoder"] {
            "autoencoder".to_string()
        } else {
            format!("policy encoder of {}", d.used_by.join(", "))
        };
        say!(
            say,
            "{who}: held-out feature error on the new frames {:.4} -> {:.4} (on the old {:.4} -> {:.4}; relative to the features' variance)",
            d.before.1,
            d.after.1,
            d.before.0,
            d.after.0
        );
        if let Some((before, after)) = d.decisions {
            say!(
                say,
                "{who}: held-out decision error on the new frames {:.4} -> {:.4} (on the old {:.4} -> {:.4}; squared noise-prediction difference)",
                before.1,
                after.1,
                before.0,
                after.0
            );
        }
    }
    say!(say, "adapted models -> {}", a.out.display());
    out_dir.finish(true)?;
    Ok(())
}

/// Writes the adapted folder: the policies with their distilled encoders, the autoencoder
/// with its, the world model, judge and `rank.toml` copied, `adaptation.json` at the root
/// and in each adapted checkpoint.
fn write_folder(
    a: &TrainAdaptArgs,
    policies: &[Policy],
    students: Vec<ObsEncoder>,
    ae: &Autoencoder,
    adaptation: &Adaptation,
) -> Result<()> {
    for ((dir, file, net, _), student) in policies.iter().zip(students) {
        let out = a.out.join("policies").join(dir.file_name().unwrap_or_default());
        let mut net = net.clone();
        net.encoder = student;
        copy_files(dir, &out, &["policy.json", "model.bpk"])?;
        write_policy(&out, file, &net)?;
        write_json(&out.join("adaptation.json"), adaptation)?;
    }
    let ae_out = a.out.join("autoencoder");
    // Its config and provenance; not its weights (written below) nor what described or resumed
    // the original training.
    let stale = [
        "model.bpk",
        "README.md",
        "optimizer.bpk",
        "state.json",
        "reconstructions.png",
        "train_log.jsonl",
        "sessions.jsonl",
    ];
    copy_files(&a.models.join("autoencoder"), &ae_out, &stale)?;
    let weights = ae_out.join("model.bpk");
    ae.clone()
        .save_file(&weights)
        .map_err(|e| crate::TrainError::Refused(format!("{}: {e}", weights.display())))?;
    write_json(&ae_out.join("adaptation.json"), adaptation)?;
    for part in ["world_model", "judge"] {
        if a.models.join(part).is_dir() {
            copy_files(&a.models.join(part), &a.out.join(part), &[])?;
        }
    }
    if a.models.join("rank.toml").is_file() {
        std::fs::copy(a.models.join("rank.toml"), a.out.join("rank.toml")).context("copying rank.toml")?;
    }
    write_json(&a.out.join("adaptation.json"), adaptation)?;
    Ok(())
}

#[cfg(test)]
#[path = "adapt_tests.rs"]
mod tests;
