//! Learner updates per second at batch 128 and batch-1 action latency, Ant-sized networks
//! (paper defaults; obs 105 = Ant-v5, obs 125 = rllab Ant; act 8). Plain `Instant` timing.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p agent --bench update`; `-- --test` runs a quick smoke pass.

use std::time::Instant;

use agent::{AgentConfig, Batch, Learner, Mode};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

fn batch(cfg: &AgentConfig, size: usize, rng: &mut StdRng) -> Batch {
    let mut draw = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.sample(StandardNormal)).collect() };
    Batch {
        size,
        observations: draw(size * cfg.obs_dim),
        actions: draw(size * cfg.act_dim).iter().map(|a: &f32| a.tanh()).collect(),
        rewards: draw(size),
        next_observations: draw(size * cfg.obs_dim),
        terminated: vec![0.0; size],
        is_weights: Some(vec![1.0; size]),
    }
}

/// (min, median, max) of `runs` windows, each `per_window` calls of `f`, in calls per second.
fn rate(runs: usize, per_window: usize, mut f: impl FnMut()) -> (f64, f64, f64) {
    let mut rates: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..per_window {
                f();
            }
            per_window as f64 / start.elapsed().as_secs_f64()
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    (rates[0], rates[runs / 2], rates[runs - 1])
}

fn main() -> agent::Result<()> {
    let quick = std::env::args().any(|a| a == "--test");
    let (warmup, runs, per_window, acts) = if quick { (2, 1, 2, 10) } else { (100, 5, 200, 20_000) };
    let threads = std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "default".into());
    println!("agent update bench (candle CPU, RAYON_NUM_THREADS={threads}), batch 128");
    let variants = [
        ("paper", 105, AgentConfig::for_task(105, 8)),
        ("paper", 125, AgentConfig::for_task(125, 8)),
        (
            "twin+reparam+alpha",
            105,
            AgentConfig {
                twin_q: true,
                reparameterize: true,
                learn_temperature: true,
                ..AgentConfig::for_task(105, 8)
            },
        ),
    ];
    for (name, obs_dim, cfg) in variants {
        let mut rng = StdRng::seed_from_u64(1);
        let b = batch(&cfg, 128, &mut rng);
        let mut learner = Learner::new(cfg.clone(), 1)?;
        for _ in 0..warmup {
            learner.update(&b)?;
        }
        let (lo, med, hi) = rate(runs, per_window, || {
            learner.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
        });
        println!(
            "update  {name:<20} obs {obs_dim:>3} act 8: {lo:7.1} / {med:7.1} / {hi:7.1} updates/s (min/median/max)"
        );

        let mut actor = learner.actor(2)?;
        let obs: Vec<f32> = b.observations[..obs_dim].to_vec();
        let one = batch(&cfg, 1, &mut rng);
        for (label, mode) in [("act explore", Mode::Explore), ("act deterministic", Mode::Deterministic)] {
            let (lo, med, hi) = rate(runs, acts, || {
                std::hint::black_box(actor.act(&obs, mode).unwrap_or_else(|e| panic!("act failed: {e}")));
            });
            println!(
                "{label:<18} obs {obs_dim:>3}: {:6.2} / {:6.2} / {:6.2} us (min/median/max)",
                1e6 / hi,
                1e6 / med,
                1e6 / lo
            );
        }
        let (lo, med, hi) = rate(runs, acts, || {
            std::hint::black_box(actor.td_errors(&one).unwrap_or_else(|e| panic!("td failed: {e}")));
        });
        println!(
            "td_errors batch 1  obs {obs_dim:>3}: {:6.2} / {:6.2} / {:6.2} us (min/median/max)",
            1e6 / hi,
            1e6 / med,
            1e6 / lo
        );
    }
    Ok(())
}
