//! One module per subcommand (`rank` and `plan`, the largest, are folders); [`run`] dispatches.

pub(crate) mod agreement;
mod collect;
mod collect_arm;
mod collect_mix;
mod collect_policy;
mod dataset;
mod dataset_merge;
mod export_policies;
mod import_judge;
mod import_policy;
mod import_robomimic;
mod import_wm;
mod merge;
pub(crate) mod plan;
pub(crate) mod rank;
mod read_judge;
mod record;
mod scripted;
mod simulate;
mod simulate_arm;
mod simulate_policy;
mod simulate_replay;
mod tasks;
mod train;
mod train_judge;
mod train_policy;
mod train_wm;
mod wm_export;

use std::process::ExitCode;

use anyhow::Result;

use crate::cli::{Cli, Command, DatasetCommand, ImportCommand, TrainCommand, WmCommand};

/// The commit this binary was built from (`+dirty` if tracked files differed from it;
/// "unknown" when built outside a git checkout), recorded by `build.rs`: the
/// provenance every command that writes a model or a score records.
pub(crate) fn git_commit() -> String {
    env!("EVALHARNESS_BUILD_COMMIT").to_string()
}

/// Runs the parsed command; the exit code is 0 unless a gate failed (1).
pub fn run(cli: &Cli) -> Result<ExitCode> {
    match &cli.command {
        Command::Simulate(a) => simulate::run(a, cli.quiet),
        Command::Collect(a) => match &a.policy {
            Some(dir) => collect_policy::run(a, dir, cli.quiet),
            None => collect::run(a, cli.quiet),
        },
        Command::Dataset(DatasetCommand::Info { path, json }) => dataset::info(path, *json),
        Command::Dataset(DatasetCommand::Merge { inputs, out, force }) => {
            dataset_merge::run(inputs, out, *force, cli.quiet)
        }
        Command::Train(t) => {
            train::stop_on_signals();
            match t {
                TrainCommand::Autoencoder(a) => train::autoencoder(a, cli.quiet),
                TrainCommand::WorldModel(a) => train_wm::run(a, cli.quiet),
                TrainCommand::Policy(a) => train_policy::run(a, cli.quiet),
                TrainCommand::Judge(a) => train_judge::run(a, cli.quiet),
            }
        }
        Command::Agreement(a) => agreement::run(a),
        Command::Rank(a) => rank::run(a, cli.render_workers, cli.quiet),
        Command::RankShard { file } => rank::run_shard(file, cli.render_workers, cli.quiet),
        Command::Plan(a) => plan::run(a, cli.quiet),
        Command::Merge(a) => merge::run(&a.shards, &a.out, a.force, a.no_report),
        Command::Tasks(a) => tasks::run(&a.runs, a.tex.as_deref(), a.force),
        // Answered in `main`, before any command runs.
        Command::RenderWorker => Ok(ExitCode::SUCCESS),
        Command::Report(a) => {
            // The report is written into the run's folder: not while a run writes there.
            let _lock = crate::output::lock::lock(&a.out)?;
            let html = runner::report::write_report(&a.out)?;
            outln!("{}", html.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Wm(WmCommand::Eval(a)) => {
            let out = wm_eval::run(a, &mut |line| outln!("{line}"))?;
            outln!("-> {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Wm(WmCommand::Export(a)) => wm_export::run(a),
        Command::Import(ImportCommand::WorldModel(a)) => import_wm::run(a),
        Command::Import(ImportCommand::Judge(a)) => import_judge::run(a),
        Command::Import(ImportCommand::Policy(a)) => import_policy::run(a),
        Command::Scripted(a) => scripted::run(a),
        Command::ExportPolicies(a) => export_policies::run(a),
        Command::ReadJudge(a) => read_judge::run(a),
    }
}
