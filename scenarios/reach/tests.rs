//! Reach's rules, checked by hand.

use harness::scripted::{FrameRequest, Scripted, Settings};
use harness::task::Env;

use super::{ReachConfig, ReachJudge, ReachTask, render};

#[test]
fn the_shipped_scene_parses_and_a_file_is_checked_by_field() {
    let cfg = ReachConfig::default();
    assert_eq!((cfg.goal, cfg.tolerance, cfg.gain, cfg.max_steps, cfg.image_size), (7.0, 0.5, 0.5, 20, 96));
    let path = std::path::Path::new("r.toml");
    let bad = "name = \"reach\"\ngoal = 12.0\ntolerance = 0.5\ngain = 0.5\nmax_steps = 20\nimage_size = 96\n";
    let err = ReachConfig::from_toml_str(bad, path).unwrap_err().to_string();
    assert!(err.contains("goal") && err.contains("r.toml"), "{err}");
    let unknown = format!("{bad}\nspeed = 2\n").replace("12.0", "7.0");
    assert!(ReachConfig::from_toml_str(&unknown, path).is_err());
}

#[test]
fn the_marker_moves_half_way_and_succeeds_near_the_goal() {
    let task = ReachTask::new(ReachConfig::default());
    let mut env = task.episode(3);
    // The start is a pure function of the seed.
    assert_eq!(env.x(), task.episode(3).x());
    assert!((0.0..10.0).contains(&env.x()));
    // From x0 commanding 7: x0 + (7 - x0)/2, then halving the rest: within 0.5 of 7 once
    // |7 - x0| / 2^k < 0.5, i.e. after ceil(log2(2 |7 - x0|)) steps (none if already there).
    let x0 = env.x();
    let need = if (7.0 - x0).abs() < 0.5 { 0 } else { (2.0 * (7.0 - x0).abs()).log2().ceil() as usize };
    let mut steps = 0;
    while env.score() < 1.0 {
        env.step(&[7.0]).unwrap();
        steps += 1;
    }
    assert_eq!(steps, need, "x0 {x0}");
    assert!(env.step(&[f32::NAN]).is_err());
    assert!(env.step(&[1.0, 2.0]).is_err());
}

#[test]
fn the_judge_reads_the_marker_back_from_the_frame() {
    // Column of x at side 96: x / 10 · 95; away from the ends the band's mean column returns
    // x within half a pixel, 10 / 95 / 2 ≈ 0.053 of the line.
    for x in [0.5, 2.5, 6.9, 7.3, 9.5] {
        let read = ReachJudge::position(&render(x, 7.0, 96)).unwrap();
        assert!((read - x).abs() < 0.06, "{x}: read {read}");
    }
    // At an end the band is cut in half: x = 0 covers columns 0..=2 (the band is 6 wide),
    // whose mean, 1, reads as 10 / 95 ≈ 0.105.
    let read = ReachJudge::position(&render(0.0, 7.0, 96)).unwrap();
    assert!((read - 10.0 / 95.0).abs() < 1e-12, "{read}");
    let task = ReachTask::new(ReachConfig::default());
    let env = task.episode(0);
    let judge = env.judge().unwrap();
    assert_eq!(judge.score(&render(7.2, 7.0, 96)), 1.0);
    assert_eq!(judge.score(&render(6.2, 7.0, 96)), 0.0);
    assert_eq!(judge.score(&[40; 96 * 96 * 3]), 0.0, "no marker");
    assert_eq!(ReachJudge::position(&[0; 10]), None);
}

#[test]
fn scripted_episodes_are_the_same_for_any_thread_count() {
    let task = ReachTask::new(ReachConfig::default());
    let work: Vec<(u64, usize)> = (0..9).map(|s| (s, (s % 2) as usize)).collect();
    let run = |jobs| {
        let settings = Settings { noise: 0.3, lag: 1, max_steps: 12, stop_at_success: true, jobs };
        let mut eps = Vec::new();
        let frames = |i| (i == 0).then_some(FrameRequest { size: 16, beside_reference: false });
        task.run(&work, &settings, &frames, &mut |i, ep| {
            eps.push((i, ep.seed, ep.steps, ep.success, ep.arrays.state.clone(), ep.frames.len()));
            Ok(())
        })
        .unwrap();
        eps
    };
    let one = run(1);
    assert_eq!(one, run(2));
    // In order, and the first episode kept its frames: one before each step and the last.
    assert_eq!(one.iter().map(|e| e.0).collect::<Vec<_>>(), (0..9).collect::<Vec<_>>());
    assert_eq!(one[0].5, one[0].2 + 1);
    assert!(one[1..].iter().all(|e| e.5 == 0));
    // The lagged expert holds still for its first step.
    let expert = &one[0];
    assert_eq!(expert.4[0], expert.4[1], "{expert:?}");
}

#[test]
fn the_task_is_reach_everywhere() {
    let task = crate::load_task("reach").unwrap();
    assert_eq!(task.name(), "reach");
    assert_eq!(task.scripted().unwrap().layout().spec.action_dim, 1);
}
