//! `evalharness read-judge`: reads a dataset's whole episodes with a learned judge as
//! `rank` reads imagined ones (the first frame and the last `--seen` of every
//! `--chunk` steps, success once it holds for k judged frames in a row), for each
//! persistence value k, against the exact label at any step. With `--out`, writes a
//! copy of the judge whose `persist_frames` is the k that reads most episodes right,
//! so the rule is chosen by a command, on data named in its provenance.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use judges::folder::{FrameJudge, JudgeFile, Label, write_judge};
use judges::metrics::{EpisodeReading, JudgeMetrics, Reading};
use judges::provenance::{JudgeProvenance, Persistence, PersistenceReport};
use judges::read::{JudgeData, judge_episodes, judged_frame_metrics, read_judged};
use judges::rule::ColourHeight;
use policies::net::NetConfig;

use super::git_commit;
use crate::cli::{JudgeRule, ReadJudgeArgs};

/// The persistence value whose reading gets most episodes right; the smallest on a tie.
fn best_persist(readings: &[EpisodeReading]) -> Option<usize> {
    readings
        .iter()
        .filter_map(|r| r.reading.map(|x| (r.agree, x.persist)))
        .max_by(|a, b| a.0.cmp(&b.0).then(b.1.cmp(&a.1)))
        .map(|(_, k)| k)
}

/// The folder file of a hand-written success rule (persistence 1 until chosen).
fn rule_file(rule: ColourHeight) -> JudgeFile {
    JudgeFile {
        pose_base: None,
        kind: "colour_height".into(),
        net: NetConfig::new().with_image_size(rule.image_size),
        rule: Some(rule),
        label: Label::Success,
        threshold: 0.5,
        persist_frames: 1,
        steps: 0,
        heldout: JudgeMetrics::default(),
        provenance: JudgeProvenance {
            commit: git_commit(),
            hand_written: Some("judges::rule::ColourHeight".into()),
            ..JudgeProvenance::default()
        },
    }
}

/// `evalharness read-judge`.
pub fn run(a: &ReadJudgeArgs) -> Result<ExitCode> {
    if a.persist.is_empty() || a.persist.contains(&0) {
        bail!("--persist {:?}: give one or more values of at least 1", a.persist);
    }
    if a.chunk == 0 || a.seen == 0 {
        bail!("--chunk and --seen must be positive");
    }
    if !a.data.exists() {
        bail!("--data {}: no such file or folder", a.data.display());
    }
    let staged = match &a.out {
        Some(out) => {
            let inputs =
                crate::output::Inputs::new().add("--data", &a.data).maybe("--judge", a.judge.as_deref());
            Some(crate::output::Staged::new(out, a.force, &inputs)?)
        }
        None => None,
    };
    let (judge, from) = match (&a.judge, a.rule) {
        (Some(dir), _) => (
            runner::inputs::read_judge_folder(dir, &burn::tensor::Device::flex())?,
            dir.display().to_string(),
        ),
        (None, Some(JudgeRule::LiftRed)) => {
            (FrameJudge::rule(rule_file(ColourHeight::lift_red())), "lift-red".into())
        }
        (None, None) => bail!("give --judge DIR or --rule"),
    };
    let data = JudgeData::load(&a.data, judge.file.label, a.episodes)?;
    if data.size != judge.image_size() {
        bail!(
            "--data {}: {1}x{1} frames, the judge {from} reads {2}x{2}",
            a.data.display(),
            data.size,
            judge.image_size()
        );
    }
    let threshold = judge.file.threshold;
    tracing::info!(episodes = data.episodes.len(), "judging the frames rank would judge");
    let frames_of = Reading { chunk: a.chunk, seen: a.seen, persist: 1 };
    let judged = judge_episodes(&judge, &data, &data.episodes, &frames_of, threshold);
    let readings: Vec<EpisodeReading> = a
        .persist
        .iter()
        .map(|&k| EpisodeReading {
            reading: Some(Reading { persist: k, ..frames_of }),
            ..read_judged(&judged, k, threshold)
        })
        .collect();
    let best = best_persist(&readings).context("no reading")?;
    let report = PersistenceReport { best, frames: judged_frame_metrics(&judged, threshold), readings };
    if let Some(staged) = staged {
        let mut file = judge.file.clone();
        file.persist_frames = best;
        file.provenance.persistence = Some(Persistence {
            command: crate::stdout::command_line().join(" "),
            commit: git_commit(),
            data: a.data.display().to_string(),
            episodes: data.episodes.len(),
            fingerprint: harness::fingerprint::folder(&a.data).ok(),
            from,
            report: report.clone(),
        });
        write_judge(staged.dir(), judge.net(), &file)?;
        let out = staged.commit()?;
        tracing::info!(persist = best, out = %out.display(), "judge written");
    }
    if a.json {
        outln!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(ExitCode::SUCCESS);
    }
    let f = &report.frames;
    let pct = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{:.1}%", 100.0 * v));
    outln!(
        "judged frames: {} ({} successes): accuracy {}, recall {}, precision {}, mean abs error {:.4}",
        f.frames,
        f.positives,
        pct(Some(f.accuracy)),
        pct(f.recall),
        pct(f.precision),
        f.mean_abs_error
    );
    outln!();
    outln!("| k | episodes read right | false successes | missed successes |");
    outln!("|---|---|---|---|");
    for r in &report.readings {
        let k = r.reading.map_or(0, |x| x.persist);
        outln!(
            "| {k} | {} of {} ({} succeed) | {} | {} |",
            r.agree,
            r.episodes,
            r.successes,
            r.false_successes,
            r.missed_successes
        );
    }
    outln!();
    outln!("most episodes read right: k = {}", report.best);
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn reading(k: usize, agree: usize) -> EpisodeReading {
        EpisodeReading { reading: Some(Reading::rank(k)), agree, ..EpisodeReading::default() }
    }

    #[test]
    fn the_best_persistence_reads_most_right_and_the_smallest_wins_a_tie() {
        // Agreements 7, 9, 9, 8 for k = 1, 2, 3, 4: k = 2 and 3 tie at 9; the smaller wins.
        let r = [reading(1, 7), reading(2, 9), reading(3, 9), reading(4, 8)];
        assert_eq!(best_persist(&r), Some(2));
        assert_eq!(best_persist(&[reading(6, 1)]), Some(6));
        assert_eq!(best_persist(&[]), None);
    }
}
