//! `evalharness train policy`: trains a diffusion policy on the dataset's expert
//! demonstrations and saves a checkpoint every `--save-every` epochs.

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use policies::data::Demos;
use policies::diffusion::{DiffusionConfig, Normalisation};
use policies::dir::{diffusion_config, read_policy_file};
use policies::net::NetConfig;
use policies::provenance::{DemosUsed, PolicyProvenance, PolicyStart};
use policies::train::{Phase, PolicyRun, PolicyTrainConfig, RunConfigs, train_policy};

use crate::args::TrainPolicyArgs;
use crate::common::{dataset_origin, dataset_task, fixed, prepare_out, refuse_contradicting_flags};
use harness::sessions::{open_session, read_step, record_session};

/// `evalharness train policy`.
pub fn run(a: &TrainPolicyArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    if a.batch == 0 || a.epochs == Some(0) || a.save_every == 0 {
        refuse!("--batch, --epochs and --save-every must be positive");
    }
    if a.ema.is_some_and(|d| !(0.0..1.0).contains(&d)) {
        refuse!("--ema must be in [0, 1), got {}", a.ema.unwrap_or_default());
    }
    let task = dataset_task(&a.data)?;
    let (ad, pd) = (task.action_spec().dim, task.observation_spec().proprio.len());
    let mut policy = DiffusionConfig {
        net: NetConfig::new()
            .with_encoder_width(a.encoder_width)
            .with_down_dims(a.down_dims.clone())
            .with_action_dim(ad)
            // Absent when it equals the action width (Push-T), as in every Push-T checkpoint.
            .with_proprio_dim((pd != ad).then_some(pd)),
        inference_steps: a.inference_steps,
        ..DiffusionConfig::default()
    };
    let start =
        a.init_from.as_deref().map(|dir| starting_checkpoint(dir, &policy, &inv.given)).transpose()?;
    if let Some(s) = &start {
        policy = s.config.clone();
    }
    // Checked before `--force` clears the output folder.
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("--data", &a.data)];
    inputs.extend(a.init_from.as_deref().map(|p| ("--init-from", p)));
    inputs.extend(a.encoder_from.as_deref().map(|p| ("--encoder-from", p)));
    let out_dir = prepare_out(&a.out, a.session.resume, a.session.force, ".train/state.json", &inputs)?;
    let behaviour = (a.behaviour != "all").then_some(a.behaviour.as_str());
    tracing::info!(data = %a.data.display(), ?behaviour, "loading demonstrations");
    let demos = Demos::load(&a.data, task.as_ref(), behaviour, a.episodes, policy.net.image_size)?;
    tracing::info!(episodes = demos.episodes.len(), samples = demos.len(), "loaded");
    let configs = run_configs(a, inv, (task.name(), policy, start.as_ref()), &demos)?;
    let args: Vec<String> = inv.command_line.clone();
    if a.session.resume {
        check_resume_flags(&a.out.join(".train").join("config.json"), &configs, &inv.given)?;
    }
    if let Some(from) = a.encoder_from.as_ref().filter(|_| !a.session.resume) {
        let dst = a.out.join(".train");
        std::fs::create_dir_all(&dst).with_context(|| format!("creating {}", dst.display()))?;
        for f in ["encoder.bpk", "encoder_optimizer.bpk", "encoder_state.json"] {
            let src = from.join(".train").join(f);
            std::fs::copy(&src, dst.join(f))
                .with_context(|| format!("--encoder-from: copying {}", src.display()))?;
        }
    }
    // Its sessions (command, commit, first and last step) in `.train/sessions.jsonl`,
    // as for the other trainers.
    let train_dir = a.out.join(".train");
    let from_step = if a.session.resume { read_step(&train_dir)? } else { 0 };
    open_session(&train_dir, &args.join(" "), &inv.commit, from_step)?;
    let pb = runner::progress::bar(1, "policy", inv.quiet);
    let run = PolicyRun {
        resume: a.session.resume,
        epochs: a.epochs,
        max_minutes: a.session.max_minutes,
        ema: a.ema,
    };
    let outcome = train_policy(&demos, &a.out, &configs, run, &nn::device::selected()?, &mut |p| {
        pb.set_length(p.total);
        pb.set_position(p.step);
        pb.set_message(match p.phase {
            Phase::Encoder => format!("encoder pose pre-training, loss {:.4}", p.loss),
            Phase::Policy => format!("epoch {} loss {:.4}", p.epoch, p.loss),
        });
    })?;
    pb.finish_and_clear();
    record_session(&train_dir, &args.join(" "), &inv.commit, (from_step, outcome.step), outcome.elapsed_s)?;
    for ck in &outcome.saved {
        say!(say, "saved {}", ck.display());
    }
    say!(
        say,
        "policy: step {}/{}{}, mean loss (last 50 steps) {:.4} -> {}",
        outcome.step,
        outcome.total,
        if outcome.step >= outcome.total { "" } else { " (stopped early; --resume continues)" },
        outcome.loss,
        a.out.display()
    );
    out_dir.finish(outcome.step >= outcome.total)?;
    Ok(())
}

/// The run's settings: the training flags, the normalisation (the data's, or the starting
/// checkpoint's), and the provenance every saved checkpoint carries.
///
/// # Errors
/// Dataset attributes that cannot be read for the provenance.
fn run_configs(
    a: &TrainPolicyArgs,
    inv: &Invocation,
    (task, policy, start): (&str, DiffusionConfig, Option<&Start>),
    demos: &Demos,
) -> Result<RunConfigs> {
    let normalisation = match &start {
        Some(s) => {
            warn_outside(&demos.normalisation(), &s.normalisation);
            s.normalisation.clone()
        }
        None => demos.normalisation(),
    };
    Ok(RunConfigs {
        train: PolicyTrainConfig {
            epochs: a.epochs.unwrap_or(20),
            save_every: a.save_every,
            batch: a.batch,
            lr: a.lr,
            warmup: 200,
            weight_decay: 1e-6,
            seed: a.seed,
            checkpoint_every: 50,
            encoder_steps: if start.is_some() { 0 } else { a.encoder_steps },
            encoder_lr: a.encoder_lr,
            ema: a.ema.unwrap_or(0.999),
            init_from: a.init_from.clone(),
        },
        normalisation,
        provenance: PolicyProvenance {
            data: Some(DemosUsed {
                behaviour: a.behaviour.clone(),
                collected_with: dataset_origin(&a.data)?,
                episodes: demos.episodes.len(),
                path: a.data.display().to_string(),
                samples: demos.len(),
                other: Default::default(),
            }),
            encoder_from: a.encoder_from.as_ref().map(|p| p.display().to_string()),
            init_from: start.map(|s| PolicyStart {
                epoch: s.epoch,
                path: s.dir.display().to_string(),
                provenance: serde_json::to_value(&s.provenance).unwrap_or_default(),
                step: s.step,
            }),
            seed: Some(a.seed),
            ..PolicyProvenance::new(inv.command_line.join(" "), inv.commit.clone())
        },
        policy,
        task: Some(task.to_string()),
    })
}

/// `--resume` continues a run with its saved `.train/config.json`: the model, data and
/// optimiser flags typed on this command line must agree with it (`--epochs`, `--ema`
/// and the session flags may change; see [`refuse_contradicting_flags`]).
fn check_resume_flags(path: &std::path::Path, fresh: &RunConfigs, given: &[String]) -> Result<()> {
    let saved: RunConfigs = harness::runfile::read(path)?;
    let (ours, theirs) = (&fresh.train, &saved.train);
    let data = |c: &RunConfigs| c.provenance.data.as_ref().map(|d| (d.behaviour.clone(), d.episodes)).unzip();
    let ((our_behaviour, our_episodes), (their_behaviour, their_episodes)) = (data(fresh), data(&saved));
    let fixed = vec![
        fixed("save_every", &ours.save_every, &theirs.save_every),
        fixed("batch", &ours.batch, &theirs.batch),
        fixed("lr", &ours.lr, &theirs.lr),
        fixed("seed", &ours.seed, &theirs.seed),
        fixed("encoder_steps", &ours.encoder_steps, &theirs.encoder_steps),
        fixed("encoder_lr", &ours.encoder_lr, &theirs.encoder_lr),
        fixed("init_from", &ours.init_from, &theirs.init_from),
        fixed("encoder_width", &fresh.policy.net.encoder_width, &saved.policy.net.encoder_width),
        fixed("down_dims", &fresh.policy.net.down_dims, &saved.policy.net.down_dims),
        fixed("inference_steps", &fresh.policy.inference_steps, &saved.policy.inference_steps),
        fixed("encoder_from", &fresh.provenance.encoder_from, &saved.provenance.encoder_from),
        fixed("behaviour", &our_behaviour, &their_behaviour),
        fixed("episodes", &our_episodes, &their_episodes),
    ];
    refuse_contradicting_flags(path, given, &fixed)
}

/// The checkpoint `--init-from` names, read and checked against the flags typed
/// with it (the network is the checkpoint's; a typed size that differs is refused).
struct Start {
    dir: std::path::PathBuf,
    config: DiffusionConfig,
    normalisation: Normalisation,
    epoch: u64,
    step: u64,
    provenance: PolicyProvenance,
}

fn starting_checkpoint(dir: &std::path::Path, typed: &DiffusionConfig, given: &[String]) -> Result<Start> {
    let file = read_policy_file(dir)?;
    let mut config = diffusion_config(dir, &file)?;
    let is_given = |id: &str| given.iter().any(|g| g == id);
    if is_given("encoder_width") && typed.net.encoder_width != config.net.encoder_width {
        refuse!(
            "--init-from {}: its encoder width is {}, not {}",
            dir.display(),
            config.net.encoder_width,
            typed.net.encoder_width
        );
    }
    if is_given("down_dims") && typed.net.down_dims != config.net.down_dims {
        refuse!(
            "--init-from {}: its U-Net has channels {:?}, not {:?}",
            dir.display(),
            config.net.down_dims,
            typed.net.down_dims
        );
    }
    if is_given("inference_steps") {
        config.inference_steps = typed.inference_steps;
    }
    Ok(Start {
        dir: dir.to_path_buf(),
        config,
        normalisation: file.normalisation,
        epoch: file.epoch,
        step: file.step,
        provenance: file.provenance,
    })
}

/// Logs a warning when the demonstrations reach outside the starting checkpoint's
/// normalisation ranges (the network then sees inputs beyond [-1, 1]).
fn warn_outside(data: &Normalisation, ck: &Normalisation) {
    for (what, d, c) in
        [("proprioception", &data.agent_pos, &ck.agent_pos), ("action", &data.action, &ck.action)]
    {
        if d.min.iter().zip(&c.min).any(|(d, c)| d < c) || d.max.iter().zip(&c.max).any(|(d, c)| d > c) {
            tracing::warn!(
                "the data's {what} range {:?}..{:?} exceeds the starting checkpoint's {:?}..{:?}; \
                 normalised values leave [-1, 1]",
                d.min,
                d.max,
                c.min,
                c.max
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use policies::symmetry::{augment_frame, augment_point, augment_pose};
    use scenarios::pusht::render::Rasterizer;
    use scenarios::pusht::{Pose2, PushTConfig, PushTState};

    /// The pre-training augmentation is exact: rendering a scene and mapping the
    /// image through a symmetry gives the rendering of the mapped scene.
    #[test]
    fn augmentation_matches_rendering_the_mapped_scene() {
        let cfg = PushTConfig::default();
        let raster = Rasterizer::new(&cfg);
        let s = raster.size();
        let (agent, block, goal) = ([120.0f32, 400.0], [300.0f32, 200.0, 0.7], [256.0f32, 256.0, -2.0]);
        let scene = |a: [f32; 2], b: [f32; 3], g: [f32; 3]| {
            let st = PushTState {
                agent: a.map(f64::from),
                agent_vel: [0.0; 2],
                block: Pose2::new(f64::from(b[0]), f64::from(b[1]), f64::from(b[2])),
            };
            raster.render(&st, &Pose2::new(f64::from(g[0]), f64::from(g[1]), f64::from(g[2])))
        };
        let frame = scene(agent, block, goal);
        for k in 0..8u8 {
            let mapped = augment_frame(&frame, s, k);
            let want = scene(augment_point(agent, k), augment_pose(block, k), augment_pose(goal, k));
            // The walls run from 5 to 506 world units, one unit off centre, so mirrored
            // walls differ in their anti-aliasing within 2 px of the border; every other
            // pixel (block, goal, agent, floor) must coincide.
            let off = (0..s * s)
                .filter(|&i| (2..s - 2).contains(&(i % s)) && (2..s - 2).contains(&(i / s)))
                .filter(|&i| (0..3).any(|c| mapped[i * 3 + c].abs_diff(want[i * 3 + c]) > 8))
                .count();
            assert_eq!(off, 0, "symmetry {k}: {off} pixels differ");
        }
    }
}
