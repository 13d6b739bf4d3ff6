//! `evalharness rank` and the hidden `rank-shard FILE` its `--processes` starts: the
//! `ranking` crate's run, told of this process (its command line, `--quiet`, stdout).

use std::path::Path;
use std::process::ExitCode;

use anyhow::Result;
use ranking::{Caller, RankArgs};

use crate::cli::Cli;

/// `evalharness rank`.
///
/// # Errors
/// What [`ranking::run`] reports.
pub fn run(cli: &Cli, a: &RankArgs) -> Result<ExitCode> {
    let inv = super::invocation(cli, Vec::new());
    Ok(ranking::run(a, cli.render_workers, &Caller { invocation: &inv, say: &|line| outln!("{line}") })?)
}

/// `evalharness rank-shard FILE`.
///
/// # Errors
/// What [`ranking::run_shard`] reports.
pub fn run_shard(cli: &Cli, file: &Path) -> Result<ExitCode> {
    let inv = super::invocation(cli, Vec::new());
    Ok(ranking::run_shard(
        file,
        cli.render_workers,
        &Caller { invocation: &inv, say: &|line| outln!("{line}") },
    )?)
}

#[cfg(test)]
mod tests {
    use std::ffi::OsString;
    use std::path::{Path, PathBuf};

    use clap::Parser;
    use ranking::args::RankArgs;
    use ranking::processes::{SHARD_COMMAND, shard_args, shard_file, shards_folder};

    fn parse(args: &[OsString]) -> RankArgs {
        let argv = std::iter::once(OsString::from("evalharness")).chain(args.iter().cloned());
        match crate::cli::Cli::try_parse_from(argv).unwrap().command {
            crate::cli::Command::Rank(r) => r,
            other => panic!("not rank: {other:?}"),
        }
    }

    #[test]
    fn a_shard_gets_every_setting_one_worker_and_no_gates() {
        let a = parse(
            &[
                "rank",
                "--scenario",
                "can",
                "--policies",
                "p",
                "--world-model",
                "w",
                "--judge",
                "j",
                "--judge-persist",
                "2",
                "--judge-every-frame",
                "--float-frames",
                "--alpha",
                "0.5",
                "--noise-scale",
                "0.25",
                "--episodes",
                "20",
                "--max-steps",
                "30",
                "--seed-start",
                "7",
                "--batch",
                "5",
                "--seed",
                "3",
                "--bootstrap",
                "100",
                "--jobs",
                "4",
                "--processes",
                "3",
                "--min-pearson",
                "0.3",
                "--max-inversions",
                "2",
                "--out",
                "o",
            ]
            .map(OsString::from),
        );
        let dir = Path::new("o.shards/shard-2");
        let s = shard_args(&a, 2, 3, dir, false);
        // Every setting of the run, as given: only the shard's own fields differ.
        let own = RankArgs {
            jobs: a.jobs,
            shard: None,
            claims: None,
            out: a.out.clone(),
            processes: a.processes,
            min_pearson: a.min_pearson,
            max_inversions: a.max_inversions,
            no_report: a.no_report,
            resume: a.resume,
            force: a.force,
            ..s.clone()
        };
        assert_eq!(own, a);
        assert_eq!((s.jobs, s.shard.as_deref(), s.processes), (1, Some("2/3"), None));
        assert_eq!((s.min_pearson, s.max_inversions, s.no_report), (None, None, true));
        assert_eq!((s.out.as_path(), s.force, s.resume), (dir, true, false));
        assert_eq!(s.claims, Some(PathBuf::from("o.shards/claims")), "the shards share one claims folder");
        let r = shard_args(&a, 0, 3, Path::new("d"), true);
        assert!(r.resume && !r.force);
        // The file round-trips, and the hidden command reads it.
        let text = serde_json::to_string(&s).unwrap();
        assert_eq!(serde_json::from_str::<RankArgs>(&text).unwrap(), s);
        assert_eq!(shard_file(dir), PathBuf::from("o.shards/shard-2.args.json"));
        let argv = ["evalharness"].into_iter().chain(SHARD_COMMAND).chain(["o.shards/shard-2.args.json"]);
        let cli = crate::cli::Cli::try_parse_from(argv).unwrap();
        assert_eq!(cli.render_workers, Some(0), "a shard renders its own frames");
        assert!(matches!(cli.command, crate::cli::Command::RankShard { .. }));
    }

    #[test]
    fn shards_go_beside_the_output() {
        assert_eq!(shards_folder(Path::new("out/can")), PathBuf::from("out/can.shards"));
    }
}
