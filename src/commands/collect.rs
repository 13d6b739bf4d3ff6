//! `evalharness collect`: a Push-T dataset in the replay-buffer zarr layout.
//!
//! Each episode's behaviour is drawn from `--mix` with a random number derived
//! from its seed, so the dataset is a pure function of the arguments, whatever
//! `--jobs` is. Images are the 96x96 observations before each action; state rows
//! are `[agent x, agent y, block x, block y, block θ, goal x, goal y, goal θ]`;
//! `data/coverage` holds the coverage after each action.

use std::process::ExitCode;

use anyhow::{Context, Result, bail};
use harness::replay::attrs::{DatasetAttrs, EpisodeEntry, Source};
use harness::replay::{EpisodeArrays, ReplaySpec};

use crate::output::dataset::StagedDataset;

use scenarios::pusht::PushTConfig;
use scenarios::pusht::rollout::Episode;

use super::collect_mix::{draw, parse_mix_with, with_source};
use crate::cli::CollectArgs;
use crate::progress;
use scenarios::pusht::runs::{BehaviourKind, FrameSpec, Perturbation, Runner, behaviour_label};

/// Names of the state columns, stored in the dataset's attributes.
pub const STATE_COLUMNS: [&str; 8] =
    ["agent_x", "agent_y", "block_x", "block_y", "block_theta", "goal_x", "goal_y", "goal_theta"];

/// Push-T's default `--mix`.
pub const PUSHT_MIX: &str = "expert=0.8,explore=0.2";

/// Parses `expert=0.8,explore=0.2` into normalised weights.
fn parse_mix(text: &str) -> Result<Vec<(BehaviourKind, f64)>> {
    parse_mix_with(text, |name| Ok(BehaviourKind::parse(name)?))
}

/// Push-T's scripted runner for `collect` and `simulate` (clap has checked `--noise` and
/// `--max-steps`: `cli::bounds`).
///
/// # Errors
/// A runner that cannot be built.
pub(super) fn pusht_runner(
    cfg: PushTConfig,
    jobs: usize,
    max_steps: Option<u32>,
    perturbation: Perturbation,
) -> Result<Runner> {
    Ok(Runner::new(cfg, jobs, max_steps, perturbation)?)
}

/// The dataset layout: `size`² RGB images, 2-D actions, 8 state columns, coverage.
pub(super) fn replay_spec(size: usize) -> ReplaySpec {
    ReplaySpec { image_hw: [size, size], action_dim: 2, state_dim: 8, extras: vec!["coverage".into()] }
}

/// One episode's arrays: the observation before each action, its state row
/// ([`STATE_COLUMNS`]), the action and the coverage after it.
pub(super) fn episode_arrays(ep: &Episode) -> EpisodeArrays {
    let steps = ep.rows.len();
    let mut arrays = EpisodeArrays::default();
    for f in &ep.frames[..steps] {
        arrays.img.extend_from_slice(f);
    }
    let g = ep.goal;
    let mut coverage = Vec::with_capacity(steps);
    for r in &ep.rows {
        arrays.action.extend(r.action.map(|v| v as f32));
        let s = [r.agent[0], r.agent[1], r.block.x, r.block.y, r.block.theta, g.x, g.y, g.theta];
        arrays.state.extend(s.map(|v| v as f32));
        coverage.push(r.coverage as f32);
    }
    arrays.extras.push(coverage);
    arrays
}

/// An episode's entry in the dataset attributes.
pub(super) fn episode_attr(ep: &Episode, behaviour: &str) -> EpisodeEntry {
    EpisodeEntry {
        seed: Some(ep.seed),
        behaviour: Some(behaviour.to_string()),
        steps: Some(ep.rows.len() as u64),
        score: Some(ep.score),
        success: Some(ep.success),
        ..EpisodeEntry::default()
    }
}

/// The dataset attributes: the layout and scenario, the seeds, how the episodes were
/// made (`source`: `collect`'s mix and perturbation, or `--policy`'s checkpoints) and
/// the episodes.
pub(super) fn dataset_attrs(
    cfg: &PushTConfig,
    seed_start: u64,
    source: Source,
    max_steps: usize,
    episodes: Vec<EpisodeEntry>,
) -> DatasetAttrs {
    let header = DatasetAttrs {
        scenario: Some("pusht".into()),
        scenario_config: serde_json::to_value(cfg).ok(),
        state_columns: Some(STATE_COLUMNS.iter().map(|c| (*c).to_string()).collect()),
        action: Some("absolute agent target position, world units".into()),
        coverage: Some("data/coverage: coverage after each action".into()),
        ..DatasetAttrs::new()
    };
    with_source(header, seed_start, source, max_steps, episodes)
}

/// `--no-early-stop` on Push-T (`collect`, `collect --policy`, `simulate`): refused, since
/// its episodes end at success or the step limit as gym-pusht's do.
///
/// # Errors
/// When the flag is set.
pub(super) fn refuse_run_on_for_pusht(no_early_stop: bool) -> Result<()> {
    if no_early_stop {
        bail!("--no-early-stop applies to Lift and Can; Push-T episodes run to their step limit or success");
    }
    Ok(())
}

/// Runs the command for the scripted behaviours (`--policy` runs [`super::collect_policy`]).
pub fn run(args: &CollectArgs, quiet: bool) -> Result<ExitCode> {
    let c = &args.common;
    let cfg =
        match scenarios::scenario(&c.scenario).with_context(|| format!("loading scenario {}", c.scenario))? {
            scenarios::Scenario::Lift(cfg) => {
                let task = scenarios::lift::LiftSim::new(cfg).context("setting up Lift")?;
                return super::collect_arm::run(args, &task, quiet);
            }
            scenarios::Scenario::Can(cfg) => {
                let task = scenarios::can::CanSim::new(cfg).context("setting up Can")?;
                return super::collect_arm::run(args, &task, quiet);
            }
            scenarios::Scenario::PushT(cfg) => *cfg,
        };
    refuse_run_on_for_pusht(args.no_early_stop)?;
    let mix_text = args.mix.as_deref().unwrap_or(PUSHT_MIX);
    let mix = parse_mix(mix_text)?;
    let perturbation = Perturbation { noise: c.noise, lag: c.lag };
    let runner = pusht_runner(cfg, c.jobs, c.max_steps, perturbation)?;
    let size = runner.cfg.render.size as usize;
    let work: Vec<(u64, BehaviourKind)> =
        harness::seed::range(c.seed_start, c.episodes)?.map(|seed| (seed, draw(&mix, seed))).collect();
    let inputs = crate::output::Inputs::new().scenario(&c.scenario);
    let mut writer = StagedDataset::create(&args.out, c.force, &inputs, replay_spec(size))?;
    let pb = progress::bar(c.episodes, "collect", quiet);
    let mut episodes = Vec::new();
    runner.run(
        &work,
        |_| Some(FrameSpec { size, beside_mujoco: false }),
        |i, ep| {
            writer.append(&episode_arrays(&ep))?;
            episodes.push(episode_attr(&ep, &behaviour_label(work[i].1, perturbation)));
            pb.inc(1);
            anyhow::Ok(())
        },
    )?;
    pb.finish_and_clear();
    let n = episodes.len();
    let source = Source {
        mix: Some(mix_text.to_string()),
        noise: Some(c.noise),
        lag: Some(c.lag as u64),
        ..Source::default()
    };
    let attrs = dataset_attrs(&runner.cfg, c.seed_start, source, runner.max_steps as usize, episodes);
    let steps = attrs.total_steps();
    let path = writer.finish(&attrs)?;
    outln!("pusht dataset: {n} episodes, {steps} steps -> {}", path.display());
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mix_parses_and_normalises() {
        let m = parse_mix("expert=3, explore=1").unwrap();
        assert_eq!(m, vec![(BehaviourKind::Expert, 0.75), (BehaviourKind::Explore, 0.25)]);
        assert!(parse_mix("expert").is_err());
        assert!(parse_mix("robot=1").is_err());
        assert!(parse_mix("expert=0").is_err());
        assert!(parse_mix("expert=x").is_err());
    }

    #[test]
    fn draws_follow_the_weights() {
        let m = parse_mix("expert=0.8,explore=0.2").unwrap();
        let experts = (0..10_000).filter(|&s| draw(&m, s) == BehaviourKind::Expert).count();
        // Binomial(10000, 0.8): std 40, so 7800..8200 is a 5-sigma band.
        assert!((7800..8200).contains(&experts), "{experts}");
        assert_eq!(draw(&m, 17), draw(&m, 17));
    }

    /// Goal-free frames (`scenarios::pusht::goal_free`) of a dataset `collect` wrote: the
    /// recorded frames without their goal, and drawing it back gives them again.
    #[test]
    fn stripped_frames_are_the_scenes_without_their_goal() {
        use clap::Parser;
        use scenarios::pusht::frame_score::FrameScorer;
        use scenarios::pusht::goal_free::{DatasetScene, strip_goal};
        use world_model::data::EpisodeData;

        use crate::cli::{Cli, Command};

        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("d.zarr");
        let p = path.to_str().unwrap();
        let args =
            ["evalharness", "-q", "collect", "--episodes", "2", "--max-steps", "12", "--mix", "explore=1"];
        let cli = Cli::try_parse_from([&args[..], &["--jobs", "1", "--out", p]].concat()).unwrap();
        let Command::Collect(c) = cli.command else { unreachable!() };
        run(&c, true).unwrap();
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
