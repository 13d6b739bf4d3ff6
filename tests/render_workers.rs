//! `--render-workers`: Lift's and Can's frames rendered in worker processes are the
//! same bytes as frames rendered in the process, so every dataset and row is too.

use std::path::Path;

use crate::util::{expect_code, run, s, tree_bytes};

/// `collect` of `task` into `out`, with `workers` render workers and 2 jobs.
fn collect(task: &str, out: &Path, workers: &str) {
    let args = ["--render-workers", workers, "collect", "--scenario", task, "--episodes", "3"];
    let mut v: Vec<&str> = args.to_vec();
    v.extend(["--max-steps", "12", "--jobs", "2", "--out", s(out)]);
    expect_code(&run(&v), 0);
}

#[test]
fn frames_from_render_workers_are_the_processes_own() {
    let tmp = tempfile::tempdir().unwrap();
    for task in ["lift", "can"] {
        let (own, pooled) = (tmp.path().join(format!("{task}_own")), tmp.path().join(format!("{task}_pool")));
        collect(task, &own, "0");
        collect(task, &pooled, "2");
        // Every array (the agentview frames included) byte for byte; the attributes
        // record the command, which differs.
        let arrays = |d: &Path| -> Vec<(String, Vec<u8>)> {
            tree_bytes(d).into_iter().filter(|(n, _)| !n.ends_with(".zattrs")).collect()
        };
        let (a, b) = (arrays(&own), arrays(&pooled));
        assert!(a.iter().any(|(n, _)| n.starts_with("data/img")), "{task}: no frames in {:?}", a.len());
        assert_eq!(a, b, "{task}: the frames differ");
    }
    let (_, err) = expect_code(&run(&["--render-workers", "65", "collect", "--out", "x"]), 2);
    assert!(err.contains("--render-workers"), "{err}");
}
