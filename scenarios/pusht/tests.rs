//! Tests of the Push-T environment that need MuJoCo.

use super::*;

fn env() -> PushTEnv {
    let cfg = PushTConfig::default();
    let model = PushTPhysics::compile(&cfg).expect("model compiles");
    PushTEnv::new(model, &cfg)
}

#[test]
fn reset_is_a_pure_function_of_the_seed() {
    let cfg = PushTConfig::default();
    assert_eq!(initial_state(&cfg, 42).unwrap(), initial_state(&cfg, 42).unwrap());
    assert_ne!(initial_state(&cfg, 42).unwrap(), initial_state(&cfg, 43).unwrap());
    let mut a = env();
    let mut b = env();
    b.reset(7).unwrap();
    a.reset(42).unwrap();
    b.reset(42).unwrap();
    assert_eq!(a.state(), b.state());
    assert_eq!(a.goal(), b.goal());
}

#[test]
fn resets_respect_the_distribution_and_never_overlap() {
    let cfg = PushTConfig::default();
    let shape = cfg.shape();
    for seed in 0..500 {
        let (s, goal) = initial_state(&cfg, seed).unwrap();
        let r = &cfg.reset;
        assert!((r.block_range[0]..r.block_range[1]).contains(&s.block.x));
        assert!((r.goal_range[0]..r.goal_range[1]).contains(&goal.y));
        assert!(s.block.theta.abs() <= std::f64::consts::PI);
        let d = shape.distance(s.block.inverse_apply(s.agent));
        assert!(d > cfg.agent.radius, "seed {seed}: agent overlaps the block ({d})");
    }
}

#[test]
fn fixed_goal_variant_uses_the_standard_goal() {
    let mut cfg = PushTConfig::default();
    cfg.reset.fixed_goal = true;
    for seed in 0..5 {
        assert_eq!(
            initial_state(&cfg, seed).unwrap().1,
            Pose2::new(256.0, 256.0, std::f64::consts::FRAC_PI_4)
        );
    }
}

#[test]
fn agent_tracks_its_target_without_touching_the_block() {
    let mut e = env();
    e.set_state(&PushTState {
        agent: [100.0, 100.0],
        agent_vel: [0.0; 2],
        block: Pose2::new(350.0, 350.0, 0.0),
    });
    for _ in 0..20 {
        e.step([150.0, 120.0]).unwrap();
    }
    let s = e.state();
    assert!((s.agent[0] - 150.0).abs() < 0.5 && (s.agent[1] - 120.0).abs() < 0.5, "{s:?}");
    assert_eq!(s.block, Pose2::new(350.0, 350.0, 0.0));
}

#[test]
fn pushing_moves_the_block_and_it_stops_when_the_agent_stops() {
    let mut e = env();
    // Agent left of the bar's left end, pushing +x along the bar's axis.
    e.set_state(&PushTState {
        agent: [150.0, 220.0],
        agent_vel: [0.0; 2],
        block: Pose2::new(256.0, 250.0, 0.0),
    });
    let mut max_pen: f64 = 0.0;
    let shape = e.config().shape();
    for k in 0..10 {
        e.step([190.0 + 6.0 * k as f64, 220.0]).unwrap();
        let s = e.state();
        let d = shape.distance(s.block.inverse_apply(s.agent));
        max_pen = max_pen.max(15.0 - d);
    }
    let moved = e.state().block;
    assert!(moved.x > 265.0, "block was not pushed: {moved:?}");
    assert!(max_pen < 3.0, "agent sank {max_pen} units into the block");
    // Agent retreats; the block must stay where it is (quasi-static).
    for _ in 0..3 {
        e.step([100.0, 100.0]).unwrap();
    }
    let a = e.state().block;
    for _ in 0..10 {
        e.step([100.0, 100.0]).unwrap();
    }
    let b = e.state().block;
    assert!((a.x - b.x).abs() < 1e-3 && (a.theta - b.theta).abs() < 1e-5, "{a:?} -> {b:?}");
}

#[test]
fn non_finite_action_is_an_error_naming_seed_and_step() {
    let mut e = env();
    e.reset(5).unwrap();
    e.step([200.0, 200.0]).unwrap();
    let err = e.step([f64::NAN, 1.0]).unwrap_err().to_string();
    assert!(err.contains("seed 5") && err.contains("step 1"), "{err}");
}

#[test]
#[ignore = "expert statistics over N seeds (env N), run by hand"]
fn expert_stats() {
    use rollout::{Record, run_episode};
    let mut e = env();
    let n: u64 = std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10);
    let mut succ = 0;
    let mut steps = 0;
    let t0 = std::time::Instant::now();
    for seed in 0..n {
        let mut ex = expert::Expert::new(e.model(), e.config());
        let ep = run_episode(&mut e, &mut ex, seed, 300, Record::default()).unwrap();
        eprintln!("seed {seed}: score {:.3} success {} steps {}", ep.score, ep.success, ep.rows.len());
        succ += ep.success as u32;
        steps += ep.rows.len();
    }
    eprintln!(
        "success {succ}/{n}, mean steps {}, {:.2}s/episode",
        steps as f64 / n as f64,
        t0.elapsed().as_secs_f64() / n as f64
    );
}

#[test]
fn expert_succeeds_on_a_few_seeds() {
    // Seeds 1, 3, 6 and 7 take the expert 80-136 steps (measured): well inside 300.
    let mut e = env();
    for seed in [1, 3, 6, 7] {
        let mut ex = expert::Expert::new(e.model(), e.config());
        let ep = rollout::run_episode(&mut e, &mut ex, seed, 300, rollout::Record::default()).unwrap();
        assert!(ep.success, "seed {seed}: score {}", ep.score);
        assert!((ep.score - 1.0).abs() < 1e-12);
    }
}

#[test]
fn lag_and_noise_perturb_the_expert_deterministically() {
    use rollout::{Behaviour, Noisy};
    let mut e = env();
    e.reset(2).unwrap();
    let start = e.state().agent;
    let mut a = Noisy::new(expert::Expert::new(e.model(), e.config()), 5.0, 2, 9);
    let mut b = Noisy::new(expert::Expert::new(e.model(), e.config()), 5.0, 2, 9);
    // The first two actions hold the agent where it is (lag 2).
    assert_eq!(a.act(&e), start);
    assert_eq!(b.act(&e), start);
    let (x, y) = (a.act(&e), b.act(&e));
    assert_eq!(x, start);
    assert_eq!(x, y);
    let (x, y) = (a.act(&e), b.act(&e));
    assert_eq!(x, y, "same seed, same noise");
    assert_ne!(x, start);
}
