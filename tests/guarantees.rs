//! The second bad-input and fault probe, as tests: each case reproduces a defect found
//! at 92f9f2b (data lost, results silently wrong, a crash) and checks the mechanism
//! `docs/guarantees.md` now states instead: inputs before outputs, the same run or
//! refuse, one writer per output, a closed pipe changes nothing.

use std::path::Path;
use std::process::Stdio;
use std::time::{Duration, Instant};

use crate::util::{evalharness, expect_code, run, s, scenario_variant, tree_bytes};

use crate::util::{pusht_inputs as inputs, tiny_rank_args as rank_args};

#[test]
fn a_resume_under_other_settings_is_refused_on_every_path() {
    // D1: `rank --processes N --resume --seed 5` over a finished seed-0 run replaced it
    // (the one-process path refused). For Lift and Can that is the default path.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let done = tmp.path().join("done");
    let mut args = rank_args(&set, &wm, &done);
    args.extend(["--processes", "2"]);
    expect_code(&run(&args), 0);
    let before = tree_bytes(&done);
    let mut again = args.clone();
    again.extend(["--seed", "5", "--resume"]);
    let (_, err) = expect_code(&run(&again), 2);
    assert!(err.contains("seed (saved: 0, now: 5)"), "{err}");
    assert_eq!(tree_bytes(&done), before, "the finished run is untouched");
    // The same settings resume to the same files (nothing left to run).
    let mut same = args.clone();
    same.push("--resume");
    expect_code(&run(&same), 0);
    let rows = |d: &Path| std::fs::read(d.join("episodes.jsonl")).unwrap();
    assert_eq!(rows(&done), before.iter().find(|(n, _)| n == "episodes.jsonl").unwrap().1);
}

#[test]
fn no_command_writes_over_its_inputs() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let ae = wm.parent().unwrap().join("autoencoder");
    let (set_before, wm_before, ae_before) = (tree_bytes(&set), tree_bytes(&wm), tree_bytes(&ae));
    let sim = |extra: &[&str]| {
        let mut v = vec!["simulate", "--policy", s(&set), "--episodes", "1", "--max-steps", "2", "--force"];
        v.extend(extra);
        run(&v)
    };
    // D2: simulate --policy P --out P --force deleted the checkpoints.
    let (_, err) = expect_code(&sim(&["--out", s(&set)]), 2);
    assert!(err.contains("is the input --policy"), "{err}");
    // ... and --replay-imagined WM --out WM the world model, --out AE its autoencoder.
    let (_, err) = expect_code(&sim(&["--replay-imagined", s(&wm), "--out", s(&wm)]), 2);
    assert!(err.contains("--replay-imagined"), "{err}");
    let (_, err) = expect_code(&sim(&["--observe-through", s(&wm), "--out", s(&ae)]), 2);
    assert!(err.contains("--observe-through's autoencoder"), "{err}");
    let inside = set.join("noise000-lag0").join("out");
    let (_, err) = expect_code(&sim(&["--out", s(&inside)]), 2);
    assert!(err.contains("lies inside the input --policy"), "{err}");
    // D4: a scenario file inside --out was deleted by --force.
    let out = tmp.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    let scene = scenario_variant(&out, "scene.toml", "max_steps = 300", "max_steps = 300");
    let (_, err) = expect_code(
        &run(&[
            "collect",
            "--scenario",
            s(&scene),
            "--episodes",
            "1",
            "--max-steps",
            "2",
            "--out",
            s(&out),
            "--force",
        ]),
        2,
    );
    assert!(err.contains("contains the input --scenario"), "{err}");
    assert!(scene.is_file());
    // D5: `dataset merge X.partial Y --out X` cleared its own input.
    let partial = tmp.path().join("x.partial");
    std::fs::create_dir_all(&partial).unwrap();
    std::fs::write(partial.join("keep.txt"), "mine").unwrap();
    let x = tmp.path().join("x");
    let (_, err) = expect_code(&run(&["dataset", "merge", s(&partial), s(&set), "--out", s(&x)]), 2);
    assert!(err.contains("keeps .partial files"), "{err}");
    assert!(partial.join("keep.txt").is_file());
    assert_eq!((tree_bytes(&set), tree_bytes(&wm), tree_bytes(&ae)), (set_before, wm_before, ae_before));
}

#[test]
fn folders_of_the_users_named_like_the_tools_are_never_cleared() {
    // D5: a user folder named OUT.shards was deleted by `rank --processes`, and a stale
    // OUT.partial by any staged command.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("r");
    let shards = tmp.path().join("r.shards");
    std::fs::create_dir_all(&shards).unwrap();
    std::fs::write(shards.join("notes.txt"), "mine").unwrap();
    let mut args = rank_args(&set, &wm, &out);
    args.extend(["--processes", "2"]);
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("was not made by evalharness"), "{err}");
    assert!(shards.join("notes.txt").is_file());
    let data = tmp.path().join("d.zarr");
    let partial = tmp.path().join("d.zarr.partial");
    std::fs::create_dir_all(&partial).unwrap();
    std::fs::write(partial.join("notes.txt"), "mine").unwrap();
    let (_, err) =
        expect_code(&run(&["collect", "--episodes", "1", "--max-steps", "2", "--out", s(&data)]), 2);
    assert!(err.contains("was not made by evalharness"), "{err}");
    assert!(partial.join("notes.txt").is_file());
}

#[test]
fn tasks_tex_keeps_existing_files_and_its_inputs() {
    // D6: `tasks RUN --tex FILE` overwrote any file, its own results.json included.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let r = tmp.path().join("r");
    expect_code(&run(&rank_args(&set, &wm, &r)), 0);
    let results = r.join("results.json");
    let before = std::fs::read(&results).unwrap();
    let (_, err) = expect_code(&run(&["tasks", s(&r), "--tex", s(&results), "--force"]), 2);
    assert!(err.contains("lies inside the input RUN"), "{err}");
    let tex = tmp.path().join("t.tex");
    std::fs::write(&tex, "mine").unwrap();
    let (_, err) = expect_code(&run(&["tasks", s(&r), "--tex", s(&tex)]), 2);
    assert!(err.contains("already exists"), "{err}");
    assert_eq!(std::fs::read_to_string(&tex).unwrap(), "mine");
    expect_code(&run(&["tasks", s(&r), "--tex", s(&tex), "--force"]), 0);
    assert!(std::fs::read_to_string(&tex).unwrap().contains("\\toprule"));
    assert_eq!(std::fs::read(&results).unwrap(), before);
}

#[test]
fn a_dangling_link_as_out_is_refused_and_kept() {
    // D7: a failed run deleted a dangling symlink given as --out; `simulate` to one
    // failed only after the whole run.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let link = tmp.path().join("link");
    std::os::unix::fs::symlink(tmp.path().join("nowhere"), &link).unwrap();
    for args in [
        rank_args(&set, &wm, &link),
        vec!["simulate", "--policy", s(&set), "--episodes", "1", "--max-steps", "2", "--out", s(&link)],
    ] {
        let (_, err) = expect_code(&run(&args), 2);
        assert!(err.contains("which does not exist"), "{err}");
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    }
}

#[test]
fn a_closed_stdout_changes_no_exit_code_and_no_file() {
    // D8: with stdout closed a failed gate exited 0 (the broken pipe's panic was
    // caught as success).
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("r");
    let mut args = rank_args(&set, &wm, &out);
    args.extend(["--min-pearson", "1"]);
    let mut child = evalharness().args(&args).stdout(Stdio::piped()).stderr(Stdio::null()).spawn().unwrap();
    drop(child.stdout.take());
    let status = child.wait().unwrap();
    // Two scripted policies, 6 steps: Pearson below 1 (or undefined), so the gate fails.
    assert_eq!(status.code(), Some(1));
    assert!(out.join("results.json").is_file() && out.join("episodes.parquet").is_file());
}

#[test]
fn a_second_writer_of_one_output_is_refused() {
    // D15: two `collect` runs into one --out could mix their episodes with exit 0.
    // The second is refused while another process holds the output's lock.
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("d.zarr");
    let lock = tmp.path().join(".d.zarr.evalharness-lock");
    let held = std::fs::File::create(&lock).unwrap();
    held.try_lock().unwrap();
    let (_, err) =
        expect_code(&run(&["collect", "--episodes", "1", "--max-steps", "2", "--out", s(&out)]), 2);
    assert!(err.contains("being written by another evalharness process"), "{err}");
    assert!(!out.exists() && !tmp.path().join("d.zarr.partial").exists());
    drop(held);
    expect_code(&run(&["collect", "--episodes", "1", "--max-steps", "2", "--out", s(&out)]), 0);
    assert!(!lock.exists(), "the lock file goes with its holder");
}

#[test]
fn a_changed_scene_file_or_an_incomplete_merge_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    // D9: resume recorded the scenario's path, not its content.
    let scene = scenario_variant(tmp.path(), "s.toml", "max_steps = 300", "max_steps = 300");
    let out = tmp.path().join("r");
    let mut args = rank_args(&set, &wm, &out);
    args.extend(["--scenario", s(&scene)]);
    let two = crate::util::with_flag(&args, "--episodes", "2");
    expect_code(&run(&two), 0);
    scenario_variant(tmp.path(), "s.toml", "radius = 15.0", "radius = 16.0");
    let mut grow = args.clone();
    grow.push("--resume");
    let (_, err) = expect_code(&run(&grow), 2);
    // The file's bytes and the parameters they load as both changed; both are named.
    assert!(err.contains("content of scenario, scenario parameters changed"), "{err}");
    // D11: merge accepted shards with a batch missing.
    let (a, b) = (tmp.path().join("s0"), tmp.path().join("s1"));
    for (i, d) in [(0, &a), (1, &b)] {
        let shard = format!("{i}/2");
        let mut v = rank_args(&set, &wm, d);
        v.extend(["--shard", shard.as_str()]);
        let code = run(&v).status.code();
        assert!(matches!(code, Some(0 | 1)), "shard {i}: {code:?}");
    }
    let jsonl = b.join("episodes.jsonl");
    let text = std::fs::read_to_string(&jsonl).unwrap();
    let kept: Vec<&str> = text.lines().skip(4).collect();
    std::fs::write(&jsonl, kept.join("\n") + "\n").unwrap();
    let m = tmp.path().join("m");
    let (_, err) = expect_code(&run(&["merge", s(&a), s(&b), "--out", s(&m)]), 2);
    assert!(err.contains("lacks rows of 2 of its 4 seeds"), "{err}");
    assert!(!m.exists());
}

#[test]
fn a_grown_run_writes_the_straight_runs_file() {
    // D22: after `--resume --episodes` growth the rows came in another order than a
    // straight run's, although the docs promised equal files.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let (grown, straight) = (tmp.path().join("g"), tmp.path().join("s"));
    let args = rank_args(&set, &wm, &grown);
    expect_code(&run(&crate::util::with_flag(&args, "--episodes", "2")), 0);
    let mut more = args.clone();
    more.push("--resume");
    expect_code(&run(&more), 0);
    expect_code(&run(&rank_args(&set, &wm, &straight)), 0);
    let rows = |d: &Path| std::fs::read(d.join("episodes.jsonl")).unwrap();
    assert_eq!(rows(&grown), rows(&straight));
}

#[test]
fn non_utf8_arguments_are_errors_not_panics() {
    // D18: rank, plan, train and others read std::env::args() to record the command
    // and panicked (exit 101) on an argument that is not UTF-8.
    use std::os::unix::ffi::OsStrExt;
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let odd = tmp.path().join(std::ffi::OsStr::from_bytes(b"out\xff"));
    let placeholder = tmp.path().join("placeholder");
    let args = rank_args(&set, &wm, &placeholder);
    let out = evalharness()
        .args(
            args.iter()
                .map(|a| if *a == s(&placeholder) { odd.as_os_str() } else { std::ffi::OsStr::new(a) }),
        )
        .output()
        .unwrap();
    expect_code(&out, 0);
    assert!(odd.join("results.json").is_file());
}

#[test]
fn shards_end_with_a_killed_parent() {
    // D21: shard processes outlived a `kill -9` of their `rank --processes` parent.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("r");
    let mut args = rank_args(&set, &wm, &out);
    args = crate::util::with_flag(&args, "--max-steps", "300");
    args = crate::util::with_flag(&args, "--episodes", "40");
    args.extend(["--processes", "2"]);
    let mut parent = evalharness().args(&args).stderr(Stdio::null()).spawn().unwrap();
    let pid = parent.id();
    let shards = || children_of(pid);
    let start = Instant::now();
    while shards().is_empty() && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(100));
    }
    let started = shards();
    assert!(!started.is_empty(), "no shard started");
    parent.kill().unwrap();
    parent.wait().unwrap();
    let start = Instant::now();
    while started.iter().any(|p| alive(*p)) && start.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(!started.iter().any(|p| alive(*p)), "shards {started:?} outlived their parent");
}

/// The processes started by `pid` as `rank --processes` shards (their environment
/// names it).
fn children_of(pid: u32) -> Vec<u32> {
    let want = format!("EVALHARNESS_PARENT_PID={pid}");
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|p| {
            std::fs::read(format!("/proc/{p}/environ"))
                .is_ok_and(|env| env.split(|&b| b == 0).any(|kv| kv == want.as_bytes()))
        })
        .collect()
}

/// Whether `pid` is still running (a zombie counts as gone).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .is_ok_and(|st| st.rsplit(')').next().is_some_and(|rest| !rest.trim_start().starts_with('Z')))
}

#[test]
fn a_resume_with_another_split_names_the_count_to_use() {
    // D22: resuming a `--processes 3` run with `--processes 2` suggested `--force`,
    // which would throw the finished batches away.
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let out = tmp.path().join("r");
    let shards = tmp.path().join("r.shards");
    std::fs::create_dir_all(shards.join("shard-0")).unwrap();
    std::fs::write(shards.join(".evalharness-owned"), "shards\n").unwrap();
    std::fs::write(shards.join("shard-0/config.json"), r#"{"shard": [0, 3]}"#).unwrap();
    let mut args = rank_args(&set, &wm, &out);
    args.extend(["--processes", "2", "--resume"]);
    let (_, err) = expect_code(&run(&args), 2);
    assert!(err.contains("resume with --processes 3") && !err.contains("--force"), "{err}");
}

#[test]
fn shards_of_different_runs_are_refused_naming_the_setting() {
    // D22: merge said only "not a shard of the same run".
    let tmp = tempfile::tempdir().unwrap();
    let (set, wm) = inputs(tmp.path());
    let (a, b) = (tmp.path().join("s0"), tmp.path().join("s1"));
    for (i, d, seed) in [(0, &a, "0"), (1, &b, "3")] {
        let shard = format!("{i}/2");
        let mut v = rank_args(&set, &wm, d);
        v.extend(["--shard", shard.as_str(), "--seed", seed]);
        let code = run(&v).status.code();
        assert!(matches!(code, Some(0 | 1)), "shard {i}: {code:?}");
    }
    let m = tmp.path().join("m");
    let (_, err) = expect_code(&run(&["merge", s(&a), s(&b), "--out", s(&m)]), 2);
    assert!(err.contains("they differ in seed"), "{err}");
}

/// A small tmpfs mounted for a test, unmounted when dropped.
struct SmallDisk(std::path::PathBuf);

impl SmallDisk {
    /// Mounts `kib` KiB of tmpfs at a new folder under `dir`. CI runs as root, as the
    /// sessions do, and mounts it; where mounting is not permitted (a user's machine
    /// without root) there is no small disk to fill, said on stderr, and `None`.
    fn mount(dir: &Path, kib: u32) -> Option<Self> {
        let at = dir.join("small");
        std::fs::create_dir_all(&at).unwrap();
        let out = std::process::Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={kib}k"), "tmpfs"])
            .arg(&at)
            .output()
            .ok()?;
        if !out.status.success() {
            eprintln!("no small disk: mounting a tmpfs failed: {}", String::from_utf8_lossy(&out.stderr));
            return None;
        }
        Some(Self(at))
    }
}

impl Drop for SmallDisk {
    fn drop(&mut self) {
        let _ = std::process::Command::new("umount").arg(&self.0).status();
    }
}

#[test]
fn a_full_disk_leaves_nothing_half_written() {
    // D22: `collect` and `dataset merge` on a full disk left OUT.partial behind.
    let tmp = tempfile::tempdir().unwrap();
    let Some(disk) = SmallDisk::mount(tmp.path(), 64) else { return };
    let out = disk.0.join("d.zarr");
    let (_, err) =
        expect_code(&run(&["collect", "--episodes", "4", "--max-steps", "80", "--out", s(&out)]), 2);
    assert!(err.contains("No space left on device"), "{err}");
    let left: Vec<_> = std::fs::read_dir(&disk.0).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}
