//! Reach's scripted behaviours and dataset layout ([`Scripted`]).
//!
//! - `expert`: commands the goal every step (with `--noise`, Gaussian noise on it; with
//!   `--lag K`, the first K commands hold the marker where it starts).
//! - `random`: a uniform target on the line, drawn afresh every 3 steps.
//!
//! The layout: `data/img` the frame before each action, `data/action` the target,
//! `data/state` the position before it, `data/success` 1 while within the tolerance of the
//! goal after it.

use harness::replay::attrs::DatasetAttrs;
use harness::replay::{EpisodeArrays, ReplaySpec};
use harness::rng::Rng;
use harness::scripted::{EpisodeSink, FrameChoice, Layout, Recorded, Scripted, ScriptedEpisode, Settings};
use harness::seed::{derive, fnv1a};
use harness::task::TaskError;
use rayon::prelude::*;
use serde::Serialize;

use super::task::{LINE, ReachTask};
use crate::error::ScenarioError;

/// The behaviours, the expert first.
const BEHAVIOURS: [&str; 2] = ["expert", "random"];

/// One line of `simulate`'s `episodes.jsonl`.
#[derive(Serialize)]
struct StepLine {
    seed: u64,
    step: usize,
    x: f64,
    action: f64,
    success: bool,
}

impl ReachTask {
    /// Runs one scripted episode.
    fn scripted_episode(
        &self,
        seed: u64,
        behaviour: usize,
        settings: &Settings,
        frame_size: Option<usize>,
    ) -> Result<ScriptedEpisode, ScenarioError> {
        let mut env = self.episode(seed);
        let start = env.x();
        let mut rng = Rng::new(derive(seed, &[fnv1a("reach/behaviour"), behaviour as u64]));
        let mut noise = Rng::new(derive(seed, &[fnv1a("reach/noise")]));
        let (mut arrays, mut lines, mut frames) = (EpisodeArrays::default(), Vec::new(), Vec::new());
        let (mut success, mut first_success, mut target) = (false, None, start);
        let image = self.cfg.image_size;
        for step in 0..settings.max_steps {
            if let Some(size) = frame_size {
                frames.push(env.frame(size));
            }
            let x = env.x();
            let mut action = match behaviour {
                0 => self.cfg.goal,
                _ => {
                    if step % 3 == 0 {
                        target = rng.uniform() * LINE;
                    }
                    target
                }
            };
            if behaviour == 0 && settings.noise > 0.0 {
                action += settings.noise * noise.normal();
            }
            if step < settings.lag {
                action = start;
            }
            let raw = env.act(action)?;
            let now = raw > 0.5;
            arrays.img.extend_from_slice(&super::render(x, self.cfg.goal, image));
            arrays.action.push(action as f32);
            arrays.state.push(x as f32);
            arrays.extras.resize(1, Vec::new());
            arrays.extras[0].push(if now { 1.0 } else { 0.0 });
            let line = StepLine { seed, step, x, action, success: now };
            lines.push(
                serde_json::to_string(&line)
                    .map_err(|e| ScenarioError::Recorded { seed, message: e.to_string() })?,
            );
            if now && first_success.is_none() {
                first_success = Some(step + 1);
            }
            success |= now;
            if now && settings.stop_at_success {
                break;
            }
        }
        if let Some(size) = frame_size {
            frames.push(env.frame(size));
        }
        Ok(ScriptedEpisode {
            seed,
            behaviour: BEHAVIOURS[behaviour].to_string(),
            steps: arrays.action.len(),
            arrays,
            score: if success { 1.0 } else { 0.0 },
            success,
            steps_to_success: first_success,
            frames,
            step_lines: lines,
            initial_state: None,
        })
    }
}

impl Scripted for ReachTask {
    fn behaviours(&self) -> Vec<&'static str> {
        BEHAVIOURS.to_vec()
    }

    fn default_mix(&self) -> String {
        "expert=0.5,random=0.5".into()
    }

    fn early_stop_optional(&self) -> bool {
        true
    }

    fn config_json(&self) -> serde_json::Value {
        serde_json::to_value(&self.cfg).unwrap_or(serde_json::Value::Null)
    }

    fn state_columns(&self) -> Vec<String> {
        vec!["x".into()]
    }

    fn layout(&self) -> Layout {
        let size = self.cfg.image_size;
        Layout {
            spec: ReplaySpec {
                image_hw: [size, size],
                action_dim: 1,
                state_dim: 1,
                extras: vec!["success".into()],
            },
            header: DatasetAttrs {
                scenario: Some("reach".into()),
                scenario_config: Some(self.config_json()),
                state_columns: Some(self.state_columns()),
                action: Some("the marker's target position on the line, 0 to 10".into()),
                success: Some(
                    "data/success: 1 while the marker is within the tolerance of the goal, after each action"
                        .into(),
                ),
                ..DatasetAttrs::new()
            },
        }
    }

    fn recorded_arrays(&self, t: &Recorded<'_>) -> Result<EpisodeArrays, TaskError> {
        t.success_arrays((self.cfg.image_size, 1, 1), 0.5).map_err(TaskError::new)
    }

    fn run(
        &self,
        work: &[(u64, usize)],
        settings: &Settings,
        frames: &FrameChoice<'_>,
        done: &mut EpisodeSink<'_>,
    ) -> Result<(), TaskError> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(settings.jobs.max(1))
            .build()
            .map_err(|e| TaskError::new(ScenarioError::Threads(e)))?;
        let batch = settings.jobs.max(1) * 4;
        for (b, chunk) in work.chunks(batch).enumerate() {
            let episodes: Vec<Result<ScriptedEpisode, ScenarioError>> = pool.install(|| {
                chunk
                    .par_iter()
                    .enumerate()
                    .map(|(k, &(seed, behaviour))| {
                        let size = frames(b * batch + k).map(|r| r.size);
                        self.scripted_episode(seed, behaviour.min(BEHAVIOURS.len() - 1), settings, size)
                    })
                    .collect()
            });
            for (k, ep) in episodes.into_iter().enumerate() {
                done(b * batch + k, ep?)?;
            }
        }
        Ok(())
    }
}
