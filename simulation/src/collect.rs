//! `evalharness collect`: a dataset of a task's scripted behaviours in the replay-buffer
//! zarr layout the task declares ([`harness::scripted::Scripted::layout`]).
//!
//! Each episode's behaviour is drawn from `--mix` with a random number derived from its
//! seed, so the dataset is a pure function of the arguments, whatever `--jobs` is.

use crate::error::{Context, Result, SimError, refuse};
use crate::{Invocation, say};
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::scripted::{FrameRequest, Scripted, Settings};
use harness::seed::{derive, fnv1a};
use harness::task::{ScoreKind, Task};

use crate::args::{CollectArgs, ScenarioArgs};
use runner::output::dataset::StagedDataset;

/// The task `--scenario` names.
///
/// # Errors
/// A scenario that does not load, naming it.
pub(super) fn load_task(spec: &str) -> Result<Box<dyn Task>> {
    scenarios::load_task(spec).with_context(|| format!("loading scenario {spec}"))
}

/// A task's scripted behaviours and dataset layout.
///
/// # Errors
/// A task without them, naming it.
pub(super) fn scripted_of(task: &dyn Task) -> Result<&dyn Scripted> {
    task.scripted()
        .with_context(|| format!("the {} task has no scripted behaviours or dataset layout", task.name()))
}

/// `--no-early-stop` on a task whose episodes end at success (Push-T's, as gym-pusht's):
/// refused, naming the task.
///
/// # Errors
/// When the flag is set for such a task.
pub(super) fn refuse_no_early_stop(task: &dyn Task, no_early_stop: bool) -> Result<()> {
    if no_early_stop && !scripted_of(task)?.early_stop_optional() {
        refuse!(
            "--no-early-stop: {} episodes end at success or their step limit; the flag applies to tasks \
             whose episodes may run on past their first success",
            task.name()
        );
    }
    Ok(())
}

/// The index of the behaviour `name` of `task`.
///
/// # Errors
/// An unknown name, listing the task's behaviours (and `more`, what else the flag takes).
pub(super) fn behaviour_index(task: &dyn Task, name: &str, more: &str) -> Result<usize> {
    let all = scripted_of(task)?.behaviours();
    all.iter().position(|b| *b == name).ok_or_else(|| {
        SimError::Refused(format!(
            "unknown {} behaviour '{name}' (built-in: {}{more})",
            task.name(),
            all.join(", ")
        ))
    })
}

/// How the scripted episodes of `task` run under the shared flags `c` (the step limit the
/// task's unless `--max-steps`; to the first success unless `--no-early-stop`).
pub(crate) fn settings(c: &ScenarioArgs, task: &dyn Task, no_early_stop: bool) -> Settings {
    Settings {
        noise: c.noise,
        lag: c.lag,
        max_steps: c.max_steps.map_or(task.max_steps(), |m| m as usize),
        stop_at_success: !no_early_stop,
        jobs: c.jobs,
    }
}

/// Parses `name=weight` pairs, naming behaviours with `parse`, into normalised weights.
fn parse_mix<K>(text: &str, parse: impl Fn(&str) -> Result<K>) -> Result<Vec<(K, f64)>> {
    let mut mix = Vec::new();
    for part in text.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        let Some((name, w)) = part.split_once('=') else {
            refuse!("--mix: '{part}' is not name=weight");
        };
        let kind = parse(name.trim()).map_err(|e| SimError::Refused(format!("--mix: {e}")))?;
        let w: f64 = w
            .trim()
            .parse()
            .map_err(|_| SimError::Refused(format!("--mix: weight '{w}' of {name} is not a number")))?;
        if !(w.is_finite() && w >= 0.0) {
            refuse!("--mix: weight of {name} must be >= 0, got {w}");
        }
        mix.push((kind, w));
    }
    let total: f64 = mix.iter().map(|(_, w)| w).sum();
    if total <= 0.0 {
        refuse!("--mix: needs at least one positive weight, got '{text}'");
    }
    Ok(mix.into_iter().map(|(k, w)| (k, w / total)).collect())
}

/// The behaviour of episode `seed`: a pure function of the seed and the mix.
fn draw<K: Copy>(mix: &[(K, f64)], seed: u64) -> K {
    let u = (derive(seed, &[fnv1a("collect/mix")]) >> 11) as f64 / (1u64 << 53) as f64;
    let mut acc = 0.0;
    for &(k, w) in mix {
        acc += w;
        if u < acc {
            return k;
        }
    }
    mix.last().map(|m| m.0).expect("a parsed mix has an entry")
}

/// A dataset's attributes from its task's own (`header`): the first seed, how the episodes
/// were made (`source`), the step limit and one entry per episode.
pub(super) fn with_source(
    header: DatasetAttrs,
    seed_start: u64,
    source: Source,
    max_steps: usize,
    episodes: Vec<EpisodeEntry>,
) -> DatasetAttrs {
    DatasetAttrs {
        seed_start: Some(seed_start),
        source,
        max_steps: Some(max_steps as u64),
        episodes,
        ..header
    }
}

/// An episode's entry in a dataset's attributes: its seed, behaviour, steps, success, and
/// for tasks scored by more than success (Push-T's coverage) its score.
pub(super) fn episode_entry(
    task: &dyn Task,
    seed: u64,
    behaviour: &str,
    steps: usize,
    (score, success): (f64, bool),
) -> EpisodeEntry {
    EpisodeEntry {
        seed: Some(seed),
        behaviour: Some(behaviour.to_string()),
        steps: Some(steps as u64),
        score: (task.score_kind() != ScoreKind::Success).then_some(score),
        success: Some(success),
        ..EpisodeEntry::default()
    }
}

/// Runs the command for the scripted behaviours (`--policy` runs [`super::collect_policy`]).
pub fn run(args: &CollectArgs, inv: &Invocation, say: &mut dyn FnMut(&str)) -> Result<bool> {
    let c = &args.common;
    let task = load_task(&c.scenario)?;
    let (task, scripted) = (task.as_ref(), scripted_of(task.as_ref())?);
    refuse_no_early_stop(task, args.no_early_stop)?;
    let mix_text = args.mix.clone().unwrap_or_else(|| scripted.default_mix());
    let mix = parse_mix(&mix_text, |name| behaviour_index(task, name, ""))?;
    let settings = settings(c, task, args.no_early_stop);
    let work: Vec<(u64, usize)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, draw(&mix, seed))).collect();
    let layout = scripted.layout();
    let size = layout.spec.image_hw[0];
    let inputs = runner::output::Inputs::new().scenario(&c.scenario);
    let mut writer = StagedDataset::create(&args.out, c.force, &inputs, layout.spec)?;
    let pb = runner::progress::bar(c.episodes, &format!("collect {}", task.name()), inv.quiet);
    let mut episodes = Vec::new();
    let frames = |_| Some(FrameRequest { size, beside_reference: false });
    scripted
        .run(&work, &settings, &frames, &mut |_, ep| {
            writer.append(&ep.arrays).map_err(|e| SimError::from(e).into_task())?;
            episodes.push(episode_entry(task, ep.seed, &ep.behaviour, ep.steps, (ep.score, ep.success)));
            pb.inc(1);
            Ok(())
        })
        .map_err(SimError::from_task)?;
    pb.finish_and_clear();
    let n = episodes.len();
    let source = Source {
        mix: Some(mix_text),
        noise: Some(c.noise),
        lag: Some(c.lag as u64),
        no_early_stop: scripted.early_stop_optional().then_some(args.no_early_stop),
        ..Source::default()
    };
    let attrs = with_source(layout.header, c.seed_start, source, settings.max_steps, episodes);
    let steps = attrs.total_steps();
    let path = writer.finish(&attrs)?;
    say!(say, "{} dataset: {n} episodes, {steps} steps -> {}", task.name(), path.display());
    Ok(true)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mix_parses_and_normalises() {
        let task = load_task("pusht").unwrap();
        let parse = |t: &str| parse_mix(t, |n| behaviour_index(task.as_ref(), n, ""));
        // Push-T's behaviours: expert 0, explore 1, decoy 2.
        assert_eq!(parse("expert=3, explore=1").unwrap(), vec![(0, 0.75), (1, 0.25)]);
        assert!(parse("expert").is_err());
        let err = parse("robot=1").unwrap_err().to_string();
        assert!(err.contains("unknown pusht behaviour 'robot' (built-in: expert, explore, decoy)"), "{err}");
        assert!(parse("expert=0").is_err());
        assert!(parse("expert=x").is_err());
    }

    #[test]
    fn draws_follow_the_weights() {
        let m = vec![(0usize, 0.8), (1, 0.2)];
        let experts = (0..10_000).filter(|&s| draw(&m, s) == 0).count();
        // Binomial(10000, 0.8): std 40, so 7800..8200 is a 5-sigma band.
        assert!((7800..8200).contains(&experts), "{experts}");
        assert_eq!(draw(&m, 17), draw(&m, 17));
    }

    #[test]
    fn the_default_mixes_are_what_the_shipped_datasets_were_collected_with() {
        // Push-T's and Lift's default mixes, as the shipped models' provenance records them.
        for (name, mix) in [
            ("pusht", "expert=0.8,explore=0.2"),
            ("lift", "expert=0.5,miss=0.1,drop=0.1,push=0.1,hesitate=0.1,random=0.1"),
        ] {
            let task = load_task(name).expect("robosuite assets (scripts/setup.sh)");
            assert_eq!(scripted_of(task.as_ref()).unwrap().default_mix(), mix, "{name}");
        }
    }

    /// Goal-free frames (`scenarios::pusht::goal_free`) of a dataset `collect` wrote: the
    /// recorded frames without their goal, and drawing it back gives them again.
    #[test]
    fn stripped_frames_are_the_scenes_without_their_goal() {
        use clap::Parser;
        use scenarios::pusht::frame_score::FrameScorer;
        use scenarios::pusht::goal_free::{DatasetScene, strip_goal};
        use world_model::data::EpisodeData;

        /// The command line of `collect` alone.
        #[derive(Parser)]
        struct Line {
            #[command(flatten)]
            args: crate::args::CollectArgs,
        }

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.zarr");
        let p = path.to_str().unwrap();
        let args = [
            "collect",
            "--episodes",
            "2",
            "--max-steps",
            "12",
            "--mix",
            "explore=1",
            "--jobs",
            "1",
            "--out",
            p,
        ];
        let c = Line::try_parse_from(args).unwrap().args;
        let inv = crate::Invocation { quiet: true, ..crate::Invocation::default() };
        run(&c, &inv, &mut |_| {}).unwrap();
        let mut data = EpisodeData::load(&path, 96).unwrap();
        let original = data.frames.clone();
        let loaded = DatasetScene::load(&path).unwrap();
        let scene = strip_goal(&path, &loaded, &mut data.frames, 96).unwrap();
        assert_eq!(scene.len(), data.len());
        let n = 96 * 96 * 3;
        for i in 0..data.len() {
            let (with, without) = (&original[i * n..(i + 1) * n], data.frame(i));
            assert!(!without.chunks_exact(3).any(|p| p == [0, 0, 0]), "frame {i}: goal pixels left");
            // Drawing the goal back gives the recorded frame (mean error below one grey
            // level: the state is stored as f32, and the goal's rim where the block or
            // agent crosses it is approximate). Wrong state columns would move the block
            // or the agent and fail this by far.
            let mut drawn = without.to_vec();
            FrameScorer::new(&scene.cfg, &scene.goal(i), 96).draw_goal(&mut drawn);
            let mean =
                with.iter().zip(&drawn).map(|(a, b)| f64::from(a.abs_diff(*b))).sum::<f64>() / n as f64;
            assert!(mean < 1.0, "frame {i}: mean |difference| {mean:.3}");
            assert!(with != without, "frame {i}: the goal was not removed");
        }
    }
}
