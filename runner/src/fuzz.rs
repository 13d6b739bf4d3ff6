//! Mutation fuzzing of every reader of files a user (or a crash) can damage: the
//! zarr store, `episodes.jsonl` (as `--resume` and `merge` read it), `results.json`
//! (as `report` reads it) and `agreement`'s CSV. Each case starts from a valid file,
//! applies a few random byte edits (flip, overwrite, insert, delete, truncate, splice
//! in a copy of a piece) and asserts that the reader returns — a value or an error —
//! without panicking.
//!
//! Cases are drawn from a fixed seed, so a failure names the case that reproduces it.
//! The run lasts `EVALHARNESS_FUZZ_SECONDS` (default 2 s in the test suite; CI's fuzz
//! step gives it 60, see `.ci/run`).

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;
use std::time::{Duration, Instant};

use harness::rng::Rng;
use harness::zarr::{ArrayReader, ArrayWriter, DType};

/// A few random edits of `bytes`.
fn mutate(bytes: &[u8], rng: &mut Rng) -> Vec<u8> {
    let mut b = bytes.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = |rng: &mut Rng, len: usize| rng.below(len.max(1) as u64) as usize;
        match rng.below(6) {
            0 if !b.is_empty() => {
                let i = at(rng, b.len());
                b[i] ^= 1 << rng.below(8);
            }
            1 if !b.is_empty() => {
                let i = at(rng, b.len());
                // Bytes that matter to parsers: digits, quotes, brackets, separators, 0xff.
                b[i] = *b"0123456789\"{}[],:-.\n\xff\0e".get(at(rng, 22)).unwrap_or(&b'0');
            }
            2 => {
                let i = at(rng, b.len() + 1);
                b.insert(i.min(b.len()), rng.below(256) as u8);
            }
            3 if !b.is_empty() => {
                let i = at(rng, b.len());
                b.remove(i);
            }
            4 => {
                let keep = at(rng, b.len() + 1);
                b.truncate(keep);
            }
            _ if !b.is_empty() => {
                let (i, j) = (at(rng, b.len()), at(rng, b.len()));
                let (lo, hi) = (i.min(j), i.max(j).min(i.min(j) + 64));
                let piece = b[lo..hi].to_vec();
                let k = at(rng, b.len() + 1).min(b.len());
                b.splice(k..k, piece);
            }
            _ => {}
        }
    }
    b
}

/// Runs `check` on mutations of `seed_bytes` until the time budget is spent; a panic
/// fails the test, naming the case.
fn fuzz(name: &str, seed_bytes: &[u8], check: impl Fn(&[u8])) {
    let secs: f64 =
        std::env::var("EVALHARNESS_FUZZ_SECONDS").ok().and_then(|s| s.parse().ok()).unwrap_or(2.0);
    let deadline = Instant::now() + Duration::from_secs_f64(secs);
    let mut case = 0u64;
    while Instant::now() < deadline {
        let mut rng = Rng::new(harness::seed::derive(case, &[harness::seed::fnv1a(name)]));
        let input = mutate(seed_bytes, &mut rng);
        if catch_unwind(AssertUnwindSafe(|| check(&input))).is_err() {
            panic!("{name}: case {case} panicked on input {:?}", String::from_utf8_lossy(&input));
        }
        case += 1;
    }
    assert!(case > 0, "{name}: no case ran");
}

#[test]
fn zarr_reader_survives_damaged_metadata_and_chunks() {
    let dir = tempfile::tempdir().unwrap();
    let arr = dir.path().join("a");
    let mut w = ArrayWriter::create(&arr, DType::F32, &[2], 3).unwrap();
    w.append(&(0..14u32).flat_map(|i| (i as f32).to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    w.finish().unwrap();
    let meta = std::fs::read(arr.join(".zarray")).unwrap();
    let chunk = std::fs::read(arr.join("0.0")).unwrap();
    let read = |d: &Path| {
        if let Ok(a) = ArrayReader::open(d) {
            let _ = a.read_f64();
        }
    };
    let work = dir.path().join("m");
    std::fs::create_dir_all(&work).unwrap();
    for f in ["0.0", "1.0", "2.0"] {
        std::fs::copy(arr.join(f), work.join(f)).unwrap();
    }
    fuzz("zarr metadata", &meta, |bytes| {
        std::fs::write(work.join(".zarray"), bytes).unwrap();
        read(&work);
    });
    std::fs::write(work.join(".zarray"), &meta).unwrap();
    fuzz("zarr chunk", &chunk, |bytes| {
        std::fs::write(work.join("0.0"), bytes).unwrap();
        read(&work);
    });
}

#[test]
fn episodes_jsonl_reader_survives_damaged_rows() {
    use harness::results::{Branch, EpisodeRow};
    use harness::rows::{read_rows, resume_rows, whole_batches};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("episodes.jsonl");
    let rows: Vec<EpisodeRow> = (0..4)
        .flat_map(|s| {
            [Branch::Sim, Branch::WorldModel].map(|b| {
                EpisodeRow::new("p", s, b, 0.5, 0.4, 0.3, 0.95, 10)
                    .with_state(&[("final_block_x", 1.0), ("goal_x", 3.0)])
            })
        })
        .collect();
    let text: String = rows.iter().map(|r| serde_json::to_string(r).unwrap() + "\n").collect();
    let batches: Vec<&[u64]> = vec![&[0, 1], &[2, 3]];
    fuzz("episodes.jsonl", text.as_bytes(), |bytes| {
        std::fs::write(&path, bytes).unwrap();
        let _ = read_rows::<EpisodeRow>(&path);
        let _ = resume_rows(&path, |r: &[EpisodeRow]| {
            whole_batches(r, &batches, crate::resume::rank_key, &crate::resume::RANK_KINDS)
        });
    });
}

#[test]
fn results_json_reader_survives_damaged_files() {
    let branch = serde_json::json!({"mean": 0.5, "ci95": [0.4, 0.6], "success_rate": 0.5,
        "success_ci95": [0.1, 0.9], "episodes": 2, "block_area": 1.0, "goal_kept": null, "agent_kept": 1.0});
    let r = serde_json::json!({
        "scenario": "pusht", "world_model": "wm", "episodes": 2, "seed_start": 5, "max_steps": 300,
        "policies": [{"name": "a", "sim": branch, "world_model": branch, "frame_scorer_mean_abs_error": 0.01}],
        "agreement": {"pearson": 0.5, "spearman": null, "kendall_tau_b": null, "rank_inversions": 0,
            "rank_inversion_fraction": 0.0, "ties": [["a", "b"]], "mmrv": 0.0, "regret_at_1": 0.0,
            "ci95": {"pearson": [0.1, 0.9], "spearman": null, "kendall_tau_b": null, "rank_inversions": null,
                "mmrv": [0.0, 0.1], "regret_at_1": null, "replicates": 10}},
        "failed_policies": [{"policy": "c", "error": "bad"}],
        "timing": {"wall_seconds": 1.0, "sim_seconds": 0.5, "world_model_seconds": 0.25,
            "world_model_ms_per_frame": 4.0, "policy_seconds": 0.1, "note": "n"},
    });
    let text = serde_json::to_vec_pretty(&r).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("results.json");
    std::fs::write(&path, &text).unwrap();
    assert!(harness::results::RankResults::read(&path).is_ok(), "the seed input reads");
    fuzz("results.json", &text, |bytes| {
        std::fs::write(&path, bytes).unwrap();
        if let Ok(res) = harness::results::RankResults::read(&path) {
            let _ = reports::summary::Summary::from_results(&res);
        }
    });
}

#[test]
fn agreement_csv_parser_survives_damaged_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scores.csv");
    let text = b"policy,predicted,actual\na,0.1,0.2\na,0.3,0.25\nb,0.5,0.6\n\"c,d\",0.9,0.8\n";
    fuzz("agreement csv", text, |bytes| {
        std::fs::write(&path, bytes).unwrap();
        let _ = crate::agreement::read_csv(&path);
    });
}
