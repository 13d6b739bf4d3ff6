//! Running many scripted Push-T episodes in parallel, deterministically.
//!
//! Episodes are processed in batches; inside a batch rayon runs them on
//! `--jobs` threads, each with its own MuJoCo data on the shared model, and the
//! results come back in seed order. Every random stream of an episode derives
//! from its seed alone, so any `--jobs` gives byte-identical outputs.

use std::sync::Arc;

use crate::cli::RendererKind;
use anyhow::{Context, Result, bail};
use harness::seed::{derive, fnv1a};
use mujoco_rs::prelude::MjModel;
use rayon::prelude::*;
use scenarios::pusht::decoy::Decoy;
use scenarios::pusht::expert::Expert;
use scenarios::pusht::explore::Explorer;
use scenarios::pusht::mj_render::{MujocoRenderer, SideBySide};
use scenarios::pusht::render::Rasterizer;
use scenarios::pusht::rollout::{Behaviour, Episode, FrameSource, Noisy, Record, run_episode};
use scenarios::pusht::{PushTConfig, PushTEnv, PushTPhysics};

/// The scripted behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BehaviourKind {
    /// The sampling-planner expert.
    Expert,
    /// Smooth random targets.
    Explore,
    /// The expert pushing the block to seeded random poses instead of the goal.
    Decoy,
}

impl BehaviourKind {
    /// Parses a behaviour name.
    pub fn parse(name: &str) -> Result<Self> {
        match name {
            "expert" => Ok(Self::Expert),
            "explore" => Ok(Self::Explore),
            "decoy" => Ok(Self::Decoy),
            other => bail!(
                "unknown policy '{other}' (built-in behaviours: expert, explore, decoy; or a checkpoint folder)"
            ),
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Expert => "expert",
            Self::Explore => "explore",
            Self::Decoy => "decoy",
        }
    }
}

/// Noise and lag applied to the expert's actions.
#[derive(Clone, Copy, Debug)]
pub struct Perturbation {
    /// Gaussian std (world units).
    pub noise: f64,
    /// Control-step lag.
    pub lag: usize,
}

/// How a dataset names an episode's behaviour: a perturbed expert is not an expert
/// demonstration (`expert+noise80+lag2`), so consumers that want clean demonstrations
/// (the policy trainer's `--behaviour expert`) can tell them apart.
pub fn behaviour_label(kind: BehaviourKind, p: Perturbation) -> String {
    let mut label = kind.name().to_string();
    if kind == BehaviourKind::Expert {
        if p.noise > 0.0 {
            label.push_str(&format!("+noise{}", p.noise));
        }
        if p.lag > 0 {
            label.push_str(&format!("+lag{}", p.lag));
        }
    }
    label
}

/// Builds the behaviour of one episode; its randomness derives from the seed only.
fn behaviour(kind: BehaviourKind, env: &PushTEnv, seed: u64, p: Perturbation) -> Box<dyn Behaviour> {
    match kind {
        BehaviourKind::Expert => {
            let expert = Expert::new(env.model(), env.config());
            if p.noise > 0.0 || p.lag > 0 {
                Box::new(Noisy::new(expert, p.noise, p.lag, derive(seed, &[fnv1a("expert/noise")])))
            } else {
                Box::new(expert)
            }
        }
        BehaviourKind::Explore => Box::new(Explorer::new(derive(seed, &[fnv1a("explore")]))),
        BehaviourKind::Decoy => {
            Box::new(Decoy::new(Expert::new(env.model(), env.config()), derive(seed, &[fnv1a("decoy")])))
        }
    }
}

/// Frames to record for one episode.
#[derive(Clone, Copy, Debug)]
pub struct FrameSpec {
    /// Side in pixels.
    pub size: usize,
    /// Renderer.
    pub renderer: RendererKind,
}

fn frame_source(model: &Arc<MjModel>, cfg: &PushTConfig, spec: FrameSpec) -> Result<Box<dyn FrameSource>> {
    let raster = Rasterizer::with_size(cfg, spec.size);
    Ok(match spec.renderer {
        RendererKind::Raster => Box::new(raster),
        RendererKind::Mujoco => {
            let mujoco = MujocoRenderer::new(model.clone(), spec.size)?;
            Box::new(SideBySide { mujoco, raster })
        }
    })
}

/// What each episode needs.
pub struct Runner {
    /// Scenario parameters.
    pub cfg: PushTConfig,
    model: Arc<MjModel>,
    pool: rayon::ThreadPool,
    /// Step limit.
    pub max_steps: u32,
    /// Expert perturbation.
    pub perturbation: Perturbation,
}

impl Runner {
    /// Compiles the model and builds a pool of `jobs` threads.
    pub fn new(
        cfg: PushTConfig,
        jobs: usize,
        max_steps: Option<u32>,
        perturbation: Perturbation,
    ) -> Result<Self> {
        if !(perturbation.noise.is_finite() && perturbation.noise >= 0.0) {
            bail!("--noise must be a finite number >= 0, got {}", perturbation.noise);
        }
        let model = PushTPhysics::compile(&cfg)?;
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(jobs.max(1))
            .build()
            .context("starting worker threads")?;
        let max_steps = max_steps.unwrap_or(cfg.task.max_steps);
        if max_steps == 0 {
            bail!("--max-steps must be at least 1");
        }
        Ok(Self { cfg, model, pool, max_steps, perturbation })
    }

    /// Runs one episode per `(seed, behaviour)` in `work`, calling `done` with each
    /// result in input order. `frames(i)` says whether to render episode i's
    /// observations, and at what size.
    pub fn run(
        &self,
        work: &[(u64, BehaviourKind)],
        frames: impl Fn(usize) -> Option<FrameSpec> + Sync,
        mut done: impl FnMut(usize, Episode) -> Result<()>,
    ) -> Result<()> {
        let batch = self.pool.current_num_threads() * 4;
        for (b, chunk) in work.chunks(batch).enumerate() {
            let results: Vec<Result<Episode>> = self.pool.install(|| {
                chunk
                    .par_iter()
                    .enumerate()
                    .map_init(
                        || PushTEnv::new(self.model.clone(), &self.cfg),
                        |env, (k, &(seed, kind))| {
                            let index = b * batch + k;
                            let mut source = frames(index)
                                .map(|spec| frame_source(&self.model, &self.cfg, spec))
                                .transpose()?;
                            let mut beh = behaviour(kind, env, seed, self.perturbation);
                            // Shorten the trait object's lifetime (no coercion happens inside an Option).
                            let frames = source.as_deref_mut().map(|s| s as &mut dyn FrameSource);
                            let record = Record { frames };
                            run_episode(env, beh.as_mut(), seed, self.max_steps, record)
                                .with_context(|| format!("episode seed {seed} ({})", kind.name()))
                        },
                    )
                    .collect()
            });
            for (k, r) in results.into_iter().enumerate() {
                done(b * batch + k, r?)?;
            }
        }
        Ok(())
    }
}
