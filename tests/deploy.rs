//! The cluster scripts under `deploy/`: the Slurm array script's body, run here for every
//! array index with Slurm's variables set, and the dependent merge script give exactly what
//! one unsharded `rank` writes. No Slurm controller is needed: the scripts only read
//! `SLURM_ARRAY_TASK_ID`, `SLURM_ARRAY_TASK_COUNT` and `SLURM_CPUS_PER_TASK`.

use std::path::Path;
use std::process::{Command, Output};

use crate::util::{expect_code, results, run, s};

/// Runs `deploy/slurm/<script>` with bash, the binary under test and `vars`.
fn slurm(script: &str, vars: &[(&str, &str)], args: &[&str]) -> Output {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("deploy/slurm").join(script);
    let mut c = Command::new("bash");
    c.arg(path).args(args).env_remove("RUST_LOG").env("NO_COLOR", "1");
    c.env("EVALHARNESS", env!("CARGO_BIN_EXE_evalharness"));
    for (k, v) in vars {
        c.env(k, v);
    }
    c.output().expect("bash runs")
}

#[test]
fn slurm_array_and_merge_equal_one_unsharded_run() {
    let tmp = tempfile::tempdir().unwrap();
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/pusht");
    // Two shipped policies of different strength, so the run has a correlation to merge.
    let set = tmp.path().join("policies");
    for name in ["epoch-0001", "epoch-0045"] {
        crate::util::copy_dir(&root.join("policies").join(name), &set.join(name));
    }
    let wm = root.join("world_model");
    let tiny = ["--episodes", "4", "--max-steps", "8", "--batch", "1", "--bootstrap", "20"];

    // One machine.
    let single = tmp.path().join("single");
    let mut args = vec!["-q", "rank", "--policies", s(&set), "--world-model", s(&wm), "--no-report"];
    args.extend(tiny);
    args.extend(["--out", s(&single)]);
    expect_code(&run(&args), 0);

    // Three array tasks (4 seeds: shards of 2, 1 and 1 batches), the paths from the
    // environment as a cluster user sets them, then the merge job.
    let out = tmp.path().join("cluster");
    let env = |i| {
        [
            ("OUT", s(&out)),
            ("POLICIES", s(&set)),
            ("WORLD_MODEL", s(&wm)),
            ("SLURM_ARRAY_TASK_ID", i),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_CPUS_PER_TASK", "1"),
        ]
    };
    for i in ["0", "1", "2"] {
        expect_code(&slurm("rank.sbatch", &env(i), &tiny), 0);
        assert!(out.join(format!("shard-{i}/episodes.jsonl")).is_file(), "shard {i} wrote no rows");
    }
    // A requeued task finds its rows and redoes nothing.
    let before = std::fs::read(out.join("shard-1/episodes.jsonl")).unwrap();
    expect_code(&slurm("rank.sbatch", &env("1"), &tiny), 0);
    assert_eq!(std::fs::read(out.join("shard-1/episodes.jsonl")).unwrap(), before);
    // Outside an array task the script refuses, naming the variable.
    let (_, err) = expect_code(&slurm("rank.sbatch", &[("OUT", s(&out))], &tiny), 1);
    assert!(err.contains("SLURM_ARRAY_TASK_ID"), "{err}");

    let merge = [("OUT", s(&out)), ("SHARDS", "3")];
    expect_code(&slurm("merge.sbatch", &merge, &["--no-report"]), 0);
    let merged = out.join("merged");
    assert_eq!(
        std::fs::read_to_string(merged.join("episodes.jsonl")).unwrap(),
        std::fs::read_to_string(single.join("episodes.jsonl")).unwrap()
    );
    // 2 policies x 4 seeds x 2 branches.
    assert_eq!(std::fs::read_to_string(merged.join("episodes.jsonl")).unwrap().lines().count(), 16);
    assert_eq!(results(&merged), results(&single));
}
