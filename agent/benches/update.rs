//! Learner updates per second at batch 128, candle vs fused, and batch-1 action latency, Ant-sized
//! networks (paper defaults; obs 105 = Ant-v5, obs 125 = rllab Ant; act 8). Plain `Instant` timing.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p agent --bench update`; `-- --test` runs a quick smoke pass.
//! The fused learner runs with its default vectorised tanh and, for comparison, with libm's
//! (`with_exact_tanh`, bit-identical to candle). `RAYON_NUM_THREADS=2` runs both learners' GEMMs
//! on two threads. No fused batch-1 forward exists: the action latency is the candle `Actor`'s,
//! which executors use.
//!
//! FLOPs are counted from the layer shapes, 2 FLOP per multiply-add:
//! * nominal (PyTorch-style, as `shared/reference/stack.md` counts): every layer evaluation the
//!   candle update runs costs 2 per MAC forward, and each one on the differentiated path another
//!   4 per MAC backward (weight and input gradients);
//! * executed: the GEMMs the fused update actually runs (shared observation product, no input
//!   gradients of first layers, no Q backward for the policy, the last coupling layer's nets reused
//!   by the inverse pass).

use std::time::Instant;

use agent::{AgentConfig, Batch, FusedLearner, Learner, Mode};
use rand::{Rng, SeedableRng, rngs::StdRng};
use rand_distr::StandardNormal;

/// One core's peak, for the fraction printed (AVX-512 FMA at this machine's clock).
const PEAK_GFLOPS: f64 = 96.0;

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

/// Nanoseconds this thread has spent on a CPU (`/proc/thread-self/schedstat`, updated at
/// scheduler ticks, so good to ~1% over a window), if readable: the machine is shared, so
/// single-threaded rates are also given per on-CPU second, which time spent descheduled does not
/// dilute. (With more threads the other workers' time would be missing: not printed.)
fn thread_cpu_ns() -> Option<u64> {
    std::fs::read_to_string("/proc/thread-self/schedstat").ok()?.split_whitespace().next()?.parse().ok()
}

/// Calls per second over `runs` windows of `per_window` calls of `f`.
#[derive(Clone, Copy, Debug)]
struct Rates {
    /// (min, median, max) by wall-clock time.
    wall: (f64, f64, f64),
    /// Median by this thread's on-CPU time.
    on_cpu: Option<f64>,
}

fn rate(runs: usize, per_window: usize, single_thread: bool, mut f: impl FnMut()) -> Rates {
    let (mut wall, mut on_cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let (start, cpu_start) = (Instant::now(), thread_cpu_ns().filter(|_| single_thread));
        for _ in 0..per_window {
            f();
        }
        wall.push(per_window as f64 / start.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (cpu_start, thread_cpu_ns())
            && b > a
        {
            on_cpu.push(per_window as f64 / ((b - a) as f64 * 1e-9));
        }
    }
    wall.sort_by(f64::total_cmp);
    on_cpu.sort_by(f64::total_cmp);
    Rates { wall: (wall[0], wall[runs / 2], wall[runs - 1]), on_cpu: on_cpu.get(on_cpu.len() / 2).copied() }
}

/// Multiply-adds per row of an MLP on `fan_in` inputs: (all layers, all but the first).
fn mlp_macs(fan_in: usize, layers: &[usize]) -> (usize, usize) {
    let mut prev = fan_in;
    let mut all = 0;
    let mut first = 0;
    for (k, &w) in layers.iter().enumerate() {
        all += prev * w;
        if k == 0 {
            first = prev * w;
        }
        prev = w;
    }
    (all, all - first)
}

/// (nominal, executed) FLOPs of one update of the paper configuration (see the module doc).
fn flops(cfg: &AgentConfig, rows: usize) -> (f64, f64) {
    let (o, d) = (cfg.obs_dim, cfg.act_dim);
    let mut critic = cfg.critic_hidden.clone();
    critic.push(1);
    let (v_all, v_rest) = mlp_macs(o, &critic);
    let (q_all, q_rest) = mlp_macs(o + d, &critic);
    let (e_all, e_rest) = mlp_macs(o, &cfg.embedding_layers);
    let context = cfg.embedding_layers.last().copied().unwrap_or(0);
    // Both nets (s and t) of each coupling layer; odd layers move the first half.
    let per_layer: Vec<usize> = (0..cfg.coupling_layers)
        .map(|i| {
            let moved = if i % 2 == 0 { d / 2 } else { d - d / 2 };
            let mut widths = cfg.coupling_hidden.clone();
            widths.push(moved);
            2 * mlp_macs(d - moved + context, &widths).0
        })
        .collect();
    let coupling: usize = per_layer.iter().sum();
    let last_coupling = per_layer.last().copied().unwrap_or(0);
    let (h_v, h_e, h_q) = (critic[0], cfg.embedding_layers[0], critic[0]);

    // candle: V-bar, Q(s, a), Q(s, a~), V, E, sampling pass, inverse pass forward; backward
    // through Q(s, a), V, E and the inverse pass.
    let forward = v_all + 2 * q_all + v_all + e_all + 2 * coupling;
    let backward = q_all + v_all + e_all + coupling;
    let nominal = (2 * forward + 4 * backward) * rows;

    // fused forward: V-bar, the stacked first layer, the rest of V and E, Q's action product and
    // rest on 2 rows per transition, the sampling pass, the inverse pass without its first layer.
    let exec_forward =
        v_all + o * (h_v + h_e + h_q) + v_rest + e_rest + 2 * (d * h_q + q_rest) + 2 * coupling
            - last_coupling;
    // fused backward: weight and input gradients of every layer but the first, weight gradients
    // only for first layers; both for every coupling net (dL/dc needs their input gradients).
    let exec_backward =
        (2 * q_rest + (o + d) * h_q) + (2 * v_rest + o * h_v) + (2 * e_rest + o * h_e) + 2 * coupling;
    let executed = 2 * (exec_forward + exec_backward) * rows;
    (nominal as f64, executed as f64)
}

fn print_rate(label: &str, r: Rates, flop: f64) {
    let (lo, med, hi) = r.wall;
    let gflops = med * flop / 1e9;
    let on_cpu = r.on_cpu.map_or(String::new(), |c| format!("; {c:7.1}/s per on-CPU second"));
    println!(
        "{label:<36} {lo:7.1} / {med:7.1} / {hi:7.1} updates/s  {gflops:5.1} GFLOP/s = {:4.1}% of peak{on_cpu}",
        100.0 * gflops / PEAK_GFLOPS
    );
}

fn main() -> agent::Result<()> {
    let quick = std::env::args().any(|a| a == "--test");
    let (warmup, runs, per_window, acts) = if quick { (2, 1, 2, 10) } else { (100, 5, 200, 20_000) };
    // Both learners use RAYON_NUM_THREADS threads for their matrix products (candle reads it
    // itself, every core when unset; the fused learner is told, 1 when unset).
    let threads: usize = std::env::var("RAYON_NUM_THREADS").ok().and_then(|t| t.parse().ok()).unwrap_or(1);
    println!(
        "agent update bench, {threads} thread(s), batch 128; peak taken as {PEAK_GFLOPS} GFLOP/s per core"
    );
    println!(
        "updates/s: min / median / max of {runs} windows of {per_window} updates; GFLOP/s of the median"
    );
    for obs_dim in [105, 125] {
        let cfg = AgentConfig::for_task(obs_dim, 8);
        let (nominal, executed) = flops(&cfg, 128);
        println!(
            "\nobs {obs_dim} act 8: {:.1} MFLOP nominal per update, {:.1} MFLOP executed by the fused update",
            nominal / 1e6,
            executed / 1e6
        );
        let mut rng = StdRng::seed_from_u64(1);
        let b = batch(&cfg, 128, &mut rng);

        let mut candle = Learner::new(cfg.clone(), 1)?;
        for _ in 0..warmup {
            candle.update(&b)?;
        }
        let r = rate(runs, per_window, threads == 1, || {
            candle.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
        });
        print_rate("candle (nominal FLOPs)", r, nominal);

        for (label, exact) in [("fused", false), ("fused, exact tanh", true)] {
            let mut fused = FusedLearner::new(cfg.clone(), 1)?.with_threads(threads).with_exact_tanh(exact);
            for _ in 0..warmup {
                fused.update(&b)?;
            }
            let r = rate(runs, per_window, threads == 1, || {
                fused.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
            });
            print_rate(&format!("{label} (executed FLOPs)"), r, executed);
        }

        let mut actor = candle.actor(2)?;
        let obs: Vec<f32> = b.observations[..obs_dim].to_vec();
        for (label, mode) in [("act explore", Mode::Explore), ("act deterministic", Mode::Deterministic)] {
            let (lo, med, hi) = rate(runs, acts, false, || {
                std::hint::black_box(actor.act(&obs, mode).unwrap_or_else(|e| panic!("act failed: {e}")));
            })
            .wall;
            println!(
                "candle {label:<18} batch 1: {:6.2} / {:6.2} / {:6.2} us (min/median/max)",
                1e6 / hi,
                1e6 / med,
                1e6 / lo
            );
        }
        let one = batch(&cfg, 1, &mut rng);
        let (lo, med, hi) = rate(runs, acts, false, || {
            std::hint::black_box(actor.td_errors(&one).unwrap_or_else(|e| panic!("td failed: {e}")));
        })
        .wall;
        println!(
            "candle td_errors        batch 1: {:6.2} / {:6.2} / {:6.2} us (min/median/max)",
            1e6 / hi,
            1e6 / med,
            1e6 / lo
        );
    }
    Ok(())
}
