//! The run scripts users copy: the cluster scripts under `deploy/` (the Slurm array script's
//! body, run here for every array index with Slurm's variables set, and the dependent merge
//! script give exactly what one unsharded `rank` writes; no Slurm controller is needed, as
//! the scripts only read `SLURM_ARRAY_TASK_ID`, `SLURM_ARRAY_TASK_COUNT` and
//! `SLURM_CPUS_PER_TASK`), and CI's correlation job, `scripts/correlation.sh`, on one task.

use std::path::Path;
use std::process::{Command, Output};

use crate::util::{expect_code, results, run, s};

/// Variables the scripts read, cleared first so that the caller's shell cannot leak into a run.
const SCRIPT_VARS: [&str; 14] = [
    "OUT",
    "PROCESSES",
    "SHARDS",
    "SCENARIO",
    "POLICIES",
    "WORLD_MODEL",
    "JUDGE",
    "EPISODES",
    "MAX_STEPS",
    "MIN_PEARSON",
    "MAX_INVERSIONS",
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_COUNT",
    "SLURM_CPUS_PER_TASK",
];

/// Runs the script at `path` (from the repository root) with bash, the binary under test
/// and `vars`.
fn script(path: &str, vars: &[(&str, &str)], args: &[&str]) -> Output {
    let mut c = Command::new("bash");
    c.arg(Path::new(env!("CARGO_MANIFEST_DIR")).join(path)).args(args);
    c.env_remove("RUST_LOG").env("NO_COLOR", "1");
    for k in SCRIPT_VARS {
        c.env_remove(k);
    }
    c.env("EVALHARNESS", env!("CARGO_BIN_EXE_evalharness"));
    for (k, v) in vars {
        c.env(k, v);
    }
    c.output().expect("bash runs")
}

/// Runs `deploy/slurm/<name>`.
fn slurm(name: &str, vars: &[(&str, &str)], args: &[&str]) -> Output {
    script(&format!("deploy/slurm/{name}"), vars, args)
}

/// Copies of two shipped Push-T policies of different strength, in `dir/policies`.
fn two_policies(dir: &Path) -> std::path::PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/pusht/policies");
    let set = dir.join("policies");
    for name in ["epoch-0001", "epoch-0045"] {
        crate::util::copy_dir(&root.join(name), &set.join(name));
    }
    set
}

#[test]
fn slurm_array_and_merge_equal_one_unsharded_run() {
    let tmp = tempfile::tempdir().unwrap();
    // Two shipped policies of different strength, so the run has a correlation to merge.
    let set = two_policies(tmp.path());
    let wm = Path::new(env!("CARGO_MANIFEST_DIR")).join("checkpoints/pusht/world_model");
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

/// Runs CI's correlation job, `scripts/correlation.sh`.
fn correlation(vars: &[(&str, &str)]) -> Output {
    script("scripts/correlation.sh", vars, &[])
}

/// The job on `set` into `out`: 2 episodes of 8 steps per policy, gated at Pearson −1 and
/// 1 inversion.
fn tiny_job<'a>(out: &'a Path, set: &'a Path) -> Vec<(&'static str, &'a str)> {
    vec![
        ("OUT", s(out)),
        ("POLICIES", s(set)),
        ("EPISODES", "2"),
        ("MAX_STEPS", "8"),
        ("MIN_PEARSON", "-1"),
        ("MAX_INVERSIONS", "1"),
    ]
}

#[test]
fn correlation_job_reports_one_task_and_never_an_earlier_runs_files() {
    let tmp = tempfile::tempdir().unwrap();
    let set = two_policies(tmp.path());
    let out = tmp.path().join("ci");
    let mut vars = tiny_job(&out, &set);
    // In 8 steps neither policy scores in MuJoCo, so Pearson is undefined and the gate fails:
    // exit 1, with the report and the table written all the same.
    let (stdout, err) = expect_code(&correlation(&vars), 1);
    assert!(err.contains("gate failed: Pearson is undefined"), "{err}");
    let report = out.join("pusht/report.html");
    assert!(report.is_file(), "no report: {stdout}");
    // rank's own last line names the report; the job's line repeats it per task.
    assert!(stdout.contains(&format!("report: {}\n", report.display())), "{stdout}");
    assert!(stdout.contains(&format!("correlation report (pusht): {}", report.display())), "{stdout}");
    // The task table names the run: 2 policies x 2 episodes on the default seeds.
    let table = std::fs::read_to_string(out.join("tasks.md")).unwrap();
    assert!(table.contains("| pusht | 2 × 2 |") && table.contains("100000–100001"), "{table}");
    assert!(out.join("tasks.tex").is_file());

    // A run that fails with an error exits 2 and does not report the files the run before it
    // left in the same folder as its own.
    std::fs::remove_file(out.join("tasks.md")).unwrap();
    let missing = tmp.path().join("no_world_model");
    vars.push(("WORLD_MODEL", s(&missing)));
    let (stdout, _) = expect_code(&correlation(&vars), 2);
    assert!(!stdout.contains("correlation report") && !stdout.contains("task table"), "{stdout}");
    assert!(!out.join("tasks.md").exists());

    // A binary that is not there is named.
    let (_, err) =
        expect_code(&correlation(&[("EVALHARNESS", "/nonexistent/evalharness"), ("OUT", s(&out))]), 2);
    assert!(err.contains("EVALHARNESS=/nonexistent/evalharness"), "{err}");
}

#[test]
fn correlation_job_resumes_a_rank_that_a_signal_killed() {
    let tmp = tempfile::tempdir().unwrap();
    let set = two_policies(tmp.path());
    let out = tmp.path().join("ci");
    // A binary that dies of SIGSEGV after its first run (as a crash inside Mesa's renderer
    // killed `rank` on 2026-11-27), then behaves: the job must resume that run once.
    let mark = tmp.path().join("crashed");
    let wrapper = tmp.path().join("crashing-evalharness");
    let body = format!(
        "#!/bin/sh\nif [ ! -e '{mark}' ]; then touch '{mark}'; '{real}' \"$@\"; kill -SEGV $$; fi\n\
         exec '{real}' \"$@\"\n",
        mark = mark.display(),
        real = env!("CARGO_BIN_EXE_evalharness"),
    );
    std::fs::write(&wrapper, body).unwrap();
    std::fs::set_permissions(&wrapper, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let mut vars = tiny_job(&out, &set);
    vars.push(("EVALHARNESS", s(&wrapper)));
    // 128 + 11 (SIGSEGV); the resumed run ends as a straight one does (the undefined Pearson
    // of 8 steps fails the gate: exit 1) and is reported.
    let (stdout, err) = expect_code(&correlation(&vars), 1);
    assert!(mark.exists());
    assert!(err.contains("rank pusht ended with exit 139; resuming it once"), "{err}");
    assert!(stdout.contains("correlation report (pusht)"), "{stdout}");
    assert_eq!(std::fs::read_to_string(out.join("pusht/episodes.jsonl")).unwrap().lines().count(), 8);
}

#[test]
fn correlation_job_in_shard_processes_equals_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    let set = two_policies(tmp.path());
    let one = tmp.path().join("one");
    let (single, _) = expect_code(&correlation(&tiny_job(&one, &set)), 1);
    // The same job with PROCESSES=2 (`rank --processes 2`: two shard processes of one policy
    // each, joined and finished as one run): the same rows, the same undefined Pearson
    // failing its gate (exit 1), the report, and the table printed once, for both policies.
    let two = tmp.path().join("two");
    let mut vars = tiny_job(&two, &set);
    vars.push(("PROCESSES", "2"));
    let (stdout, err) = expect_code(&correlation(&vars), 1);
    assert!(err.contains("gate failed: Pearson is undefined"), "{err}");
    assert!(err.contains("rank pusht: ") && err.contains("in 2 process(es)"), "{err}");
    let rows = |dir: &Path| std::fs::read_to_string(dir.join("pusht/episodes.jsonl")).unwrap();
    assert_eq!(rows(&two), rows(&one));
    assert_eq!(rows(&two).lines().count(), 8);
    assert!(two.join("pusht/report.html").is_file(), "{stdout}");
    assert!(!two.join("pusht.shards").exists(), "the shards' folders are left");
    // The shards print nothing; the resumed run prints what the one process did.
    assert!(single.contains("Pearson n/a"), "{single}");
    assert_eq!(stdout.matches("Pearson").count(), single.matches("Pearson").count(), "{stdout}");
    assert!(stdout.contains("epoch-0001") && stdout.contains("epoch-0045"), "{stdout}");
    assert!(stdout.contains("correlation report (pusht)") && stdout.contains("task table"), "{stdout}");
}
