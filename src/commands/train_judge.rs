//! `evalharness train judge`: trains a learned judge of imagined frames on a
//! dataset's frames and its exact per-step label, and writes the judge folder
//! (`judge.json` with its held-out metrics and provenance, `model.bpk`,
//! `log.jsonl`) only once training is complete.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use judges::folder::{JudgeFile, Label, write_judge};
use judges::metrics::JudgeMetrics;
use judges::provenance::{JudgeProvenance, LabelledData};
use judges::read::JudgeData;
use judges::train::{JudgeTrainConfig, train_judge};
use policies::net::NetConfig;

use super::git_commit;
use super::train::dataset_origin;
use crate::cli::{JudgeLabelArg, TrainJudgeArgs};
use crate::progress;

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
    (label, threshold): (Label, f64),
    data: &JudgeData,
    net: NetConfig,
    cfg: &JudgeTrainConfig,
) -> Result<JudgeFile> {
    let frames = data.labels.len();
    let args: Vec<String> = crate::stdout::command_line();
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
            commit: git_commit(),
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
fn say_result(a: &TrainJudgeArgs, (label, threshold): (Label, f64), heldout: &JudgeMetrics) {
    let pct = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1}%", 100.0 * v));
    let whole = heldout.episodes.map_or(String::new(), |e| {
        format!(
            "; whole episodes (success held for {} judged frame(s)): {} of {} read right ({} succeed; {} false successes, {} missed)",
            a.persist, e.agree, e.episodes, e.successes, e.false_successes, e.missed_successes
        )
    });
    outln!(
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
pub fn run(a: &TrainJudgeArgs, quiet: bool) -> Result<ExitCode> {
    if a.steps == 0 || a.batch == 0 || a.eval_every == 0 || a.persist == 0 {
        bail!("--steps, --batch, --eval-every and --persist must be positive");
    }
    if !(a.lr.is_finite() && a.lr > 0.0) {
        bail!("--lr {}: must be a positive number", a.lr);
    }
    if !a.data.exists() {
        bail!("--data {}: no such file or folder", a.data.display());
    }
    // Written into OUT.partial; an old OUT is replaced only once the judge is complete.
    let staged =
        crate::output::Staged::new(&a.out, a.force, &crate::output::Inputs::new().add("--data", &a.data))?;
    let label = label_of(a)?;
    let threshold = match label {
        Label::Coverage => 0.95,
        Label::Success => 0.5,
    };
    tracing::info!(data = %a.data.display(), ?label, "loading frames");
    let data = JudgeData::load(&a.data, label, a.episodes)?;
    let frames = data.labels.len();
    tracing::info!(episodes = data.episodes.len(), frames, "loaded");
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
    let mut file = judge_file(a, (label, threshold), &data, net, &cfg)?;
    let clock = harness::driver::Clock::start(a.max_minutes);
    let mut out_of_time = || clock.out_of_time();
    let pb = progress::bar(a.steps, "judge", quiet);
    let device = nn::device::selected()?;
    let outcome = train_judge(
        &data,
        &a.data,
        &file,
        &cfg,
        &staged.file("log.jsonl"),
        &mut out_of_time,
        &device,
        &mut |s, l| {
            pb.set_position(s);
            pb.set_message(format!("loss {l:.4}"));
        },
    );
    pb.finish_and_clear();
    let Some((net, heldout, steps)) = outcome? else {
        bail!(
            "stopped before the judge's first step, or by Ctrl-C; nothing was written (a judge does not resume)"
        );
    };
    file.heldout = heldout;
    file.steps = steps;
    if steps < a.steps {
        file.provenance.out_of_time = Some(format!(
            "--max-minutes {} ended training at step {steps} of {}",
            a.max_minutes.unwrap_or(0.0),
            a.steps
        ));
    }
    write_judge(staged.dir(), Some(&net), &file)?;
    staged.commit()?;
    say_result(a, (label, threshold), &heldout);
    Ok(ExitCode::SUCCESS)
}
