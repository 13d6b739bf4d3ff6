//! `evalharness train judge`: trains a learned judge of imagined frames on a
//! dataset's frames and its exact per-step label, and writes the judge folder
//! (`judge.json` with its held-out metrics and provenance, `model.bpk`, `log.jsonl`)
//! when each session ends, with the run's resumable state in `.train/`
//! ([`judges::run`]): `--resume` goes on from a session that ran out of time or was
//! stopped, as the other trainers do.

use crate::error::{Context, Result, refuse};
use crate::{Invocation, say};
use judges::folder::{JudgeFile, Label, write_judge};
use judges::metrics::JudgeMetrics;
use judges::provenance::{JudgeProvenance, LabelledData};
use judges::read::JudgeData;
use judges::run::JudgeRunConfig;
use judges::train::{JudgeSession, JudgeTrainConfig, train_judge};
use policies::net::NetConfig;

use crate::args::{JudgeLabelArg, TrainJudgeArgs};
use crate::common::{dataset_origin, fixed, prepare_out, refuse_contradicting_flags};
use harness::driver::Clock;
use harness::sessions::{open_session, read_step, record_session};

/// The label `--label` names, or the one the dataset has (coverage first).
fn label_of(a: &TrainJudgeArgs) -> Result<Label> {
    if let Some(l) = a.label {
        return Ok(match l {
            JudgeLabelArg::Coverage => Label::Coverage,
            JudgeLabelArg::Success => Label::Success,
        });
    }
    let r = harness::replay::ReplayReader::open(&a.data)
        .with_context(|| format!("--data {}", a.data.display()))?;
    let names = r.extra_names().with_context(|| format!("--data {}", a.data.display()))?;
    [Label::Coverage, Label::Success].into_iter().find(|l| names.iter().any(|n| n == l.array())).with_context(
        || format!("--data {}: no data/coverage or data/success array to learn from", a.data.display()),
    )
}

/// The judge file of a run `a` asks for (its label and threshold, its network `net`, trained
/// with `cfg` on `data`), with its provenance; the metrics are filled in after training.
///
/// # Errors
/// Dataset attributes that cannot be read for the provenance.
fn judge_file(
    a: &TrainJudgeArgs,
    inv: &Invocation,
    (label, threshold): (Label, f64),
    data: &JudgeData,
    net: NetConfig,
    cfg: &JudgeTrainConfig,
) -> Result<JudgeFile> {
    let frames = data.labels.len();
    let args: Vec<String> = inv.command_line.clone();
    Ok(JudgeFile {
        pose_base: None,
        kind: "learned".into(),
        net,
        rule: None,
        label,
        threshold,
        persist_frames: a.persist,
        steps: a.steps,
        heldout: JudgeMetrics::default(),
        provenance: JudgeProvenance {
            command: Some(args.join(" ")),
            commit: inv.commit.clone(),
            data: Some(LabelledData {
                collected_with: dataset_origin(&a.data)?,
                episodes: data.episodes.len(),
                fingerprint: harness::fingerprint::folder(&a.data).ok(),
                frames,
                held_out: harness::provenance::HELD_OUT.to_string(),
                path: a.data.display().to_string(),
                other: Default::default(),
            }),
            seed: Some(a.seed),
            train: Some(cfg.clone()),
            ..JudgeProvenance::default()
        },
    })
}

/// The held-out metrics, said in one line.
fn say_result(
    a: &TrainJudgeArgs,
    (label, threshold): (Label, f64),
    heldout: &JudgeMetrics,
    say: &mut dyn FnMut(&str),
) {
    let pct = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1}%", 100.0 * v));
    let whole = heldout.episodes.map_or(String::new(), |e| {
        format!(
            "; whole episodes (success held for {} judged frame(s)): {} of {} read right ({} succeed; {} false successes, {} missed)",
            a.persist, e.agree, e.episodes, e.successes, e.false_successes, e.missed_successes
        )
    });
    say!(
        say,
        "judge of {}: held-out {} frames ({} above {threshold}): mean abs error {:.4}, accuracy {}, recall {}, precision {}{whole} -> {}",
        label.array(),
        heldout.frames,
        heldout.positives,
        heldout.mean_abs_error,
        pct(Some(heldout.accuracy)),
        pct(heldout.recall),
        pct(heldout.precision),
        a.out.display()
    );
}

/// `evalharness train judge`.
pub fn run(a: &TrainJudgeArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<()> {
    if a.steps == 0 || a.batch == 0 || a.eval_every == 0 || a.persist == 0 {
        refuse!("--steps, --batch, --eval-every and --persist must be positive");
    }
    if !(a.lr.is_finite() && a.lr > 0.0) {
        refuse!("--lr {}: must be a positive number", a.lr);
    }
    if !a.data.exists() {
        refuse!("--data {}: no such file or folder", a.data.display());
    }
    // The dataset is read before `--out` is touched, so a refused run leaves it as it was.
    let label = label_of(a)?;
    let threshold = match label {
        Label::Coverage => 0.95,
        Label::Success => 0.5,
    };
    tracing::info!(data = %a.data.display(), ?label, "loading frames");
    let data = JudgeData::load(&a.data, label, a.episodes)?;
    tracing::info!(episodes = data.episodes.len(), frames = data.labels.len(), "loaded");
    let net = NetConfig::new()
        .with_image_size(data.size)
        .with_encoder_width(a.encoder_width)
        .with_feature_dim(a.feature_dim);
    let cfg = JudgeTrainConfig {
        steps: a.steps,
        batch: a.batch,
        lr: a.lr,
        seed: a.seed,
        balance: !a.no_balance,
        symmetries: a.symmetries,
        eval_every: a.eval_every,
    };
    let fresh =
        JudgeRunConfig { judge: judge_file(a, inv, (label, threshold), &data, net, &cfg)?, train: cfg };
    let (resume, force) = (a.session.resume, a.session.force);
    let out_dir = prepare_out(&a.out, resume, force, ".train/state.json", &[("--data", &a.data)])?;
    let train_dir = a.out.join(".train");
    if resume {
        check_resume_flags(&train_dir.join("config.json"), &fresh, &inv.given)?;
    }
    let given = &inv.given;
    let steps = given.iter().any(|g| g == "steps").then_some(a.steps);
    let run = judges::run::resume_or_start(&train_dir, fresh, resume, steps)?;
    let args = inv.command_line.clone().join(" ");
    let from_step = if resume { read_step(&train_dir)? } else { 0 };
    open_session(&train_dir, &args, &inv.commit, from_step)?;
    let pb = runner::progress::bar(run.train.steps, "judge", inv.quiet);
    pb.set_position(from_step);
    let session = JudgeSession { dir: &train_dir, resume, clock: Clock::start(a.session.max_minutes) };
    let outcome = train_judge(
        &data,
        &a.data,
        &run.judge,
        &run.train,
        &a.out.join("log.jsonl"),
        session,
        &nn::device::selected()?,
        &mut |s, l| {
            pb.set_position(s);
            pb.set_message(format!("loss {l:.4}"));
        },
    )?;
    pb.finish_and_clear();
    let sessions =
        record_session(&train_dir, &args, &inv.commit, (from_step, outcome.step), outcome.elapsed_s)?;
    let total = run.train.steps;
    let finished = outcome.step >= total;
    let Some((net, heldout)) = outcome.judge else {
        say!(say, "judge: stopped before its first step; --resume continues -> {}", a.out.display());
        out_dir.finish(false)?;
        return Ok(());
    };
    let mut file = run.judge;
    file.heldout = heldout;
    file.steps = outcome.step;
    file.provenance.sessions = sessions;
    file.provenance.out_of_time = (!finished).then(|| {
        format!(
            "the last session stopped at step {} of {total} (--max-minutes or Ctrl-C); --resume continues",
            outcome.step
        )
    });
    write_judge(&a.out, Some(&net), &file)?;
    say_result(a, (label, threshold), &heldout, say);
    if !finished {
        say!(say, "judge: step {} of {total} (stopped early; --resume continues)", outcome.step);
    }
    out_dir.finish(finished)?;
    Ok(())
}

/// `--resume` continues a run with its saved `.train/config.json`: the flags typed on this
/// command line must agree with it (`--steps` and the session flags may change; see
/// [`refuse_contradicting_flags`]).
fn check_resume_flags(path: &std::path::Path, fresh: &JudgeRunConfig, given: &[String]) -> Result<()> {
    let saved: JudgeRunConfig = harness::runfile::read(path)?;
    let (ours, theirs) = (&fresh.train, &saved.train);
    let (our_net, their_net) = (&fresh.judge.net, &saved.judge.net);
    let episodes = |c: &JudgeRunConfig| c.judge.provenance.data.as_ref().map(|d| d.episodes);
    let fixed = [
        fixed("label", &fresh.judge.label, &saved.judge.label),
        fixed("batch", &ours.batch, &theirs.batch),
        fixed("lr", &ours.lr, &theirs.lr),
        fixed("seed", &ours.seed, &theirs.seed),
        fixed("no_balance", &!ours.balance, &!theirs.balance),
        fixed("symmetries", &ours.symmetries, &theirs.symmetries),
        fixed("eval_every", &ours.eval_every, &theirs.eval_every),
        fixed("encoder_width", &our_net.encoder_width, &their_net.encoder_width),
        fixed("feature_dim", &our_net.feature_dim, &their_net.feature_dim),
        fixed("persist", &fresh.judge.persist_frames, &saved.judge.persist_frames),
        fixed("episodes", &episodes(fresh), &episodes(&saved)),
    ];
    refuse_contradicting_flags(path, given, &fixed)
}
