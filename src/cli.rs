//! Command-line interface (clap derive). Doc comments are the help text.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

pub use runner::bounds;
pub use runner::bounds::bootstrap_replicates;
mod judge;
mod plan;
mod rank;
pub use importers::args::*;
pub use judge::*;
pub use plan::*;
pub use rank::*;
pub use ranking::args::RankArgs;
pub use simulation::args::*;
pub use trainers::args::*;

/// Rank robot-policy checkpoints offline in a learned world model (DriftWorld),
/// checked against a MuJoCo reference simulator.
#[derive(Debug, Parser)]
#[command(name = "evalharness", version, about)]
pub struct Cli {
    /// More logging (-v debug, -vv trace). RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Only warnings and errors on stderr, no progress bars.
    #[arg(short, long, global = true)]
    pub quiet: bool,
    /// Render Lift's and Can's frames in this many worker processes, so that `--jobs`
    /// threads render at once (one process renders one frame at a time); the frames are
    /// the same bytes. 0: in this process.
    /// [default: 0; `rank`: the task's `rank.toml`, 2 for Lift and Can]
    #[arg(long, global = true, value_name = "N", value_parser = bounds::count(0, 64))]
    pub render_workers: Option<usize>,
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The ids of the arguments given on this process's command line (not defaulted)
/// of the subcommand at `path`, e.g. `["train", "world-model"]`: re-parses
/// `std::env::args_os()`, so a `--resume` can tell a flag the user typed from a default.
pub fn given_on_command_line(path: &[&str]) -> Vec<String> {
    use clap::CommandFactory;
    use clap::parser::ValueSource;
    let Ok(mut m) = Cli::command().try_get_matches_from(std::env::args_os()) else {
        return Vec::new();
    };
    for name in path {
        match m.subcommand_matches(name) {
            Some(sub) => m = sub.clone(),
            None => return Vec::new(),
        }
    }
    m.ids()
        .filter(|id| m.value_source(id.as_str()) == Some(ValueSource::CommandLine))
        .map(|id| id.to_string())
        .collect()
}

/// evalharness commands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// A render worker of `--render-workers` (started by evalharness itself; requests on
    /// stdin, frames on stdout).
    #[command(hide = true)]
    RenderWorker,
    /// One shard process of `rank --processes` (started by evalharness itself): the
    /// shard's whole `rank` arguments, typed, in a JSON file.
    #[command(hide = true)]
    RankShard {
        /// The file `rank --processes` wrote (`OUT.shards/shard-I.args.json`).
        file: PathBuf,
    },
    /// Run episodes in the MuJoCo reference simulator and score them.
    Simulate(SimulateArgs),
    /// Collect a dataset (zarr replay buffer) from a mix of scripted behaviours.
    Collect(CollectArgs),
    /// Inspect datasets.
    #[command(subcommand)]
    Dataset(DatasetCommand),
    /// Train models.
    #[command(subcommand)]
    Train(TrainCommand),
    /// Agreement metrics (Pearson, Spearman, Kendall τ_b, inversions, MMRV, regret@1, mean
    /// absolute error, CIs)
    /// between predicted and actual policy scores in a CSV; JSON on stdout.
    Agreement(AgreementArgs),
    /// Join `rank --shard i/n` outputs into what one unsharded run writes.
    Merge(MergeArgs),
    /// Re-render a rank run's report (plots, table.tex, summary.csv, report.html) from its files.
    Report(ReportArgs),
    /// The paper's table of tasks from several rank runs (one row each: task, Pearson,
    /// Spearman, inversions, MMRV); Markdown on stdout, LaTeX with `--tex`.
    Tasks(TasksArgs),
    /// World-model tools.
    #[command(subcommand)]
    Wm(WmCommand),
    /// Convert models trained by other code (the official DriftWorld checkpoints) into
    /// evalharness's folders.
    #[command(subcommand)]
    Import(ImportCommand),
    /// Rank policy checkpoints in the world model, checked against MuJoCo (paired episodes).
    Rank(RankArgs),
    /// GPC-RANK planning: a policy proposes several action chunks per decision, the
    /// world model imagines each, the best is executed in MuJoCo; against no planning
    /// and against MuJoCo imagining the same proposals, on the same seeds.
    Plan(PlanArgs),
    /// Write scripted-policy checkpoints: the expert acting from frames, with action
    /// noise and lag, one per combination — a graded policy set without training.
    Scripted(ScriptedArgs),
    /// Read a dataset's whole episodes with a learned judge as `rank` reads imagined
    /// ones (the frames the policy sees, k in a row), for several persistence values k;
    /// with `--out`, a copy of the judge with the k that reads most episodes right.
    ReadJudge(ReadJudgeArgs),
    /// Copy diffusion-policy checkpoints (e.g. chosen epochs of a training run) into a
    /// policy set, optionally with other inference settings; weights are copied as they are.
    ExportPolicies(ExportPoliciesArgs),
}

/// `evalharness export-policies`.
#[derive(Debug, Args)]
pub struct ExportPoliciesArgs {
    /// A checkpoint or a folder of them (a `train policy --out` folder, or a set).
    #[arg(long)]
    pub from: PathBuf,
    /// Training epochs to export, comma-separated (default: every checkpoint).
    #[arg(long, value_delimiter = ',')]
    pub epochs: Vec<u64>,
    /// Predicted actions executed per decision (the rest are re-planned).
    #[arg(long)]
    pub action_horizon: Option<usize>,
    /// DDIM steps per decision.
    #[arg(long)]
    pub inference_steps: Option<usize>,
    /// Output folder (one sub-folder per checkpoint, named as in `--from`).
    #[arg(long)]
    pub out: PathBuf,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
    /// Add the checkpoints to an existing set `--out` (names it already holds are refused).
    #[arg(long, conflicts_with = "force")]
    pub add: bool,
    /// Prefix for the exported folder names (e.g. `ft-` for a fine-tuning run's epochs
    /// next to the run they started from).
    #[arg(long, default_value = "")]
    pub prefix: String,
}

/// `evalharness scripted`.
#[derive(Debug, Args)]
pub struct ScriptedArgs {
    /// Output folder (one `noiseNNN-lagK/` checkpoint per combination).
    #[arg(long)]
    pub out: PathBuf,
    /// Action noise standard deviations (world units), comma-separated.
    #[arg(long, default_value = "0", value_delimiter = ',')]
    pub noise: Vec<f64>,
    /// Control steps each decision holds still before the plan, comma-separated.
    #[arg(long, default_value = "0", value_delimiter = ',')]
    pub lag: Vec<usize>,
    /// Actions per decision.
    #[arg(long, default_value_t = 8)]
    pub action_horizon: usize,
    /// Replace an existing `--out`.
    #[arg(long)]
    pub force: bool,
}

/// `evalharness agreement`.
#[derive(Debug, Args)]
pub struct AgreementArgs {
    /// CSV with columns policy,predicted,actual (one row per episode or per policy).
    #[arg(long)]
    pub csv: PathBuf,
    /// Bootstrap replicates for the 95% intervals (1 to 1,000,000).
    #[arg(long, default_value_t = 2000, value_parser = bootstrap_replicates)]
    pub bootstrap: usize,
    /// Bootstrap seed.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
}

/// `evalharness wm ...`.
#[derive(Debug, Subcommand)]
pub enum WmCommand {
    /// Video quality (MSE, PSNR, SSIM, ms/frame) of world models on held-out episodes.
    Eval(wm_eval::Options),
    /// Copy a training run's inference files (EMA weights, config, logs, provenance)
    /// into a folder to ship, its autoencoder path rewritten.
    Export(WmExportArgs),
}

/// `evalharness wm export`.
#[derive(Debug, Args)]
pub struct WmExportArgs {
    /// The training run's folder (`train world-model --out`).
    #[arg(long)]
    pub from: PathBuf,
    /// The new world-model folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Use this autoencoder instead of the run's: one with the same encoder (checked:
    /// it must encode exactly as the run's does) and another decoder, e.g. a narrower
    /// one from `train autoencoder --encoder-from`.
    #[arg(long)]
    pub autoencoder: Option<PathBuf>,
    /// The inference strength α the exported model uses (an `--accentuation` model
    /// only; a finite value >= 1): the one chosen on validation episodes, instead of
    /// the run's `--alpha`. `rank --alpha` and `wm eval --alpha` still override it.
    #[arg(long)]
    pub alpha: Option<f32>,
    /// Replace an existing output folder.
    #[arg(long)]
    pub force: bool,
}

/// `evalharness tasks`.
#[derive(Debug, Args)]
pub struct TasksArgs {
    /// `rank` output folders (with results.json), one per row, in order.
    #[arg(required = true)]
    pub runs: Vec<PathBuf>,
    /// Also write the table as booktabs LaTeX to this file.
    #[arg(long)]
    pub tex: Option<PathBuf>,
    /// Replace an existing `--tex` file.
    #[arg(long)]
    pub force: bool,
}

#[cfg(test)]
mod bounds_tests {
    use clap::Parser;

    /// The ranges of `runner::bounds` on the command line.
    #[test]
    fn counts_out_of_range_are_refused_by_flag() {
        // Each of these was accepted at 92f9f2b (and panicked inside burn, or could
        // abort on memory or spawn without end).
        for argv in [
            "evalharness rank --jobs 0",
            "evalharness rank --jobs 100000",
            "evalharness rank --processes 1000",
            "evalharness rank --batch 0",
            "evalharness plan --proposals 1000000000",
            "evalharness train judge --data d --out o --feature-dim 0",
            "evalharness train judge --data d --out o --encoder-width 0",
            "evalharness train judge --data d --out o --batch 100000000",
        ] {
            let flag = argv.split_whitespace().rev().nth(1).unwrap();
            let e = super::Cli::try_parse_from(argv.split_whitespace()).unwrap_err().to_string();
            assert!(e.contains(flag), "{argv}: {e}");
        }
        super::Cli::try_parse_from("evalharness rank --jobs 2 --processes 3".split_whitespace()).unwrap();
    }
}
