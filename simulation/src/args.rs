//! `simulate`, `collect` and `dataset` arguments (clap `Args`): the scenario, episodes, seeds
//! and threads every one of them takes, and each command's own flags. The binary flattens
//! them into its command line; the commands here read them typed.

use std::path::PathBuf;

use clap::{Args, Subcommand};
use runner::bounds;

/// Options shared by commands that run a scenario.
#[derive(Debug, Args)]
pub struct ScenarioArgs {
    /// Scenario name (pusht, pusht-gpc, lift, can, reach) or path to a scenario .toml file.
    #[arg(long, default_value = "pusht")]
    pub scenario: String,
    /// Number of episodes.
    #[arg(long, default_value_t = 10)]
    pub episodes: u64,
    /// Seed of the first episode; episode i uses seed-start + i.
    #[arg(long, default_value_t = 100_000)]
    pub seed_start: u64,
    /// Step limit per episode (default: the scenario's, 300 for Push-T).
    #[arg(long, value_parser = bounds::steps())]
    pub max_steps: Option<u32>,
    /// Worker threads (results are identical for any value).
    #[arg(long, default_value_t = default_jobs(), value_parser = bounds::workers())]
    pub jobs: usize,
    /// Replace the output if it exists.
    #[arg(long)]
    pub force: bool,
    /// Gaussian noise (std, world units) added to the expert's actions.
    #[arg(long, default_value_t = 0.0, value_parser = bounds::std_dev)]
    pub noise: f64,
    /// Control-step lag applied to the expert's actions.
    #[arg(long, default_value_t = 0)]
    pub lag: usize,
}

/// Which renderer draws recorded frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum RendererKind {
    /// The anti-aliased 2-D rasteriser (the observations).
    Raster,
    /// MuJoCo's OpenGL renderer beside the rasteriser (frames twice as wide).
    Mujoco,
}

/// `evalharness simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Scenario, episodes, seeds, jobs.
    #[command(flatten)]
    pub common: ScenarioArgs,
    /// Behaviour to run: `expert` (sampling planner), `explore` (smooth random targets),
    /// `decoy` (the expert pushing to random poses instead of the goal), or a policy checkpoint folder / folder of checkpoints (scores each checkpoint).
    #[arg(long, default_value = "expert")]
    pub policy: String,
    /// With a policy folder: write each checkpoint's measured MuJoCo score into its
    /// `provenance.json`.
    #[arg(long)]
    pub record_scores: bool,
    /// Output directory: summary.json, episodes.jsonl, config.json and a GIF of the first episode.
    #[arg(long)]
    pub out: PathBuf,
    /// Side in pixels of the GIF frames.
    #[arg(long, default_value_t = 256, value_parser = bounds::count(16, 1024))]
    pub gif_size: usize,
    /// Renderer of the GIF: `raster` (the observations' 2-D rasteriser) or `mujoco`
    /// (MuJoCo's OpenGL renderer beside the rasteriser, a visual cross-check; also
    /// writes render_crosscheck.json).
    #[arg(long, value_enum, default_value_t = RendererKind::Raster)]
    pub renderer: RendererKind,
    /// Lift: keep stepping after the cube is lifted, up to the step limit (by
    /// default an episode ends at its first success, as robomimic's rollouts do).
    #[arg(long)]
    pub no_early_stop: bool,
    /// With a policy checkpoint: the policy sees every real frame as this world
    /// model's autoencoder renders it (encoded and decoded, no dynamics), while
    /// MuJoCo scores exactly. How much of a policy's imagined behaviour is the codec's
    /// blur, apart from the world model's dynamics.
    #[arg(long, value_name = "WORLD_MODEL")]
    pub observe_through: Option<PathBuf>,
    /// With a policy checkpoint: run each episode three ways from the same state — the
    /// policy in MuJoCo, the policy in this world model (as `rank` imagines it), and the
    /// imagined episode's actions replayed in MuJoCo — so that an imagined success
    /// whose actions also succeed in MuJoCo (the imagined frames made the policy act
    /// better) is told apart from one whose actions fail there (the imagined dynamics
    /// forgave them). Writes replay.json and replay.jsonl.
    #[arg(long, value_name = "WORLD_MODEL", conflicts_with_all = ["observe_through", "record_scores"])]
    pub replay_imagined: Option<PathBuf>,
    /// With a policy checkpoint: master seed of the policies' sampling noise, as `rank
    /// --seed` (the same value gives the episodes of `rank`'s branches) [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// With --replay-imagined: the learned judge of imagined frames [default, for a task
    /// without a judge of its own (Lift, Can): checkpoints/<task>/judge].
    #[arg(long, requires = "replay_imagined")]
    pub judge: Option<PathBuf>,
    /// With --replay-imagined: the world model's sampling-noise scale, as `rank
    /// --noise-scale` [default: the model's, else 1].
    #[arg(long, value_name = "T", requires = "replay_imagined")]
    pub noise_scale: Option<f32>,
    /// With --replay-imagined: also write the replays (the imagined actions stepped in
    /// MuJoCo, to a success or the last imagined action) as a dataset in `collect`'s layout,
    /// each episode labelled `CHECKPOINT/imagined-actions`: training data in which the
    /// actions a policy takes on a world model's frames meet their real outcome.
    #[arg(long, value_name = "DATASET", requires = "replay_imagined")]
    pub record: Option<PathBuf>,
}

impl SimulateArgs {
    /// The paths this command reads, with their flags, checked against `--out` before it is
    /// touched: the scenario file, the policy folder, the judge and the world models.
    pub fn inputs(&self) -> runner::output::Inputs {
        let policy = std::path::Path::new(&self.policy);
        let mut inputs = runner::output::Inputs::new()
            .scenario(&self.common.scenario)
            .maybe("--policy", policy.exists().then_some(policy))
            .maybe("--judge", self.judge.as_deref());
        for (flag, wm) in
            [("--observe-through", &self.observe_through), ("--replay-imagined", &self.replay_imagined)]
        {
            if let Some(wm) = wm {
                inputs = inputs.world_model(flag, wm);
            }
        }
        inputs
    }
}

/// `evalharness collect`.
#[derive(Debug, Args)]
pub struct CollectArgs {
    /// Scenario, episodes, seeds, jobs.
    #[command(flatten)]
    pub common: ScenarioArgs,
    /// Behaviour mix, as name=weight pairs; each episode draws one from its seed.
    /// Push-T: expert, explore, decoy (default expert=0.8,explore=0.2). Lift:
    /// expert, miss, drop, push, hesitate, random, explore (default
    /// expert=0.5,miss=0.1,drop=0.1,push=0.1,hesitate=0.1,random=0.1). Can: also
    /// wrong-bin. Lift's and Can's `explore` (never in the default mix) is the
    /// expert with a smooth random drift and lapses: the twists and wandering of
    /// failing learned policies.
    #[arg(long)]
    pub mix: Option<String>,
    /// Instead of `--mix`: record the closed-loop MuJoCo rollouts of a policy
    /// checkpoint, or of every checkpoint in a folder (`--episodes` each, the seeds
    /// and noise of `rank`'s MuJoCo branch). Use checkpoints outside the set you
    /// will rank, so the world model does not see the ranked policies' behaviour.
    #[arg(long, conflicts_with = "mix")]
    pub policy: Option<PathBuf>,
    /// Lift and Can: keep stepping after the first success, up to the step limit (by
    /// default an episode ends at its first success), so that success lasts in the
    /// data: frames for a judge of success, and for a world model that must show it.
    /// Also with `--policy`.
    #[arg(long)]
    pub no_early_stop: bool,
    /// Output zarr folder (diffusion_policy / GPC replay-buffer layout).
    #[arg(long)]
    pub out: PathBuf,
}

/// `evalharness dataset ...`.
#[derive(Debug, Subcommand)]
pub enum DatasetCommand {
    /// Episodes, steps, shapes and score statistics of a dataset.
    Info {
        /// The zarr dataset folder.
        path: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
    },
    /// Concatenate datasets (same image size, dims, extras and scenario) into one,
    /// episodes in argument order; each keeps its seed, behaviour and source.
    Merge {
        /// The input zarr dataset folders (at least two).
        #[arg(required = true, num_args = 2..)]
        inputs: Vec<PathBuf>,
        /// Output zarr folder.
        #[arg(long)]
        out: PathBuf,
        /// Replace the output if it exists.
        #[arg(long)]
        force: bool,
    },
}

/// The default `--jobs`: the cores this process may use.
pub fn default_jobs() -> usize {
    std::thread::available_parallelism().map(usize::from).unwrap_or(1)
}
