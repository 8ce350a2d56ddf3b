//! Learner updates per second, candle vs fused, for the configurations the deploy run files train,
//! and batch-1 action latency. Plain `Instant` timing; the two learners' windows are interleaved so
//! that their ratio is measured under the same machine load.
//!
//! `RAYON_NUM_THREADS=1 cargo bench -p agent --bench update`; `-- --test` runs a quick smoke pass.
//! For each configuration it prints one line
//! `<config> fused: <N> updates/s, candle: <M> updates/s, ratio <R>` (medians), then the default's
//! fused rate against the paper's. The configurations are the [agent] tables of
//! `deploy/configs/ant-v5-paper.toml` (the dissertation's), `deploy/configs/ant-v5.toml` (the
//! default run: reparameterised, twin Q, learned temperature, uniform prior) and
//! `deploy/configs/ant-rllab.toml` (obs 125), with Ant's dimensions.
//! The fused learner runs with its default vectorised tanh and, for comparison, with libm's
//! (`with_exact_tanh`, bit-identical to candle). `RAYON_NUM_THREADS=2` runs both learners' GEMMs
//! on two threads. No fused batch-1 forward exists: the action latency is the candle `Actor`'s,
//! which executors use.
//!
//! With `UPDATE_BENCH_CHECKPOINT=<learner checkpoint of the default run file>` it also times the
//! fused update from that trained state with subnormals flushed to zero (the learner's default)
//! and without, and prints `trained checkpoint fused, flush: <N> updates/s, no flush: <M>
//! updates/s, ratio <R>` (a trained learner's Adam moments hold thousands of subnormal values).
//! With `UPDATE_BENCH_BATCHES=64,128,256` it times the default's fused update at those batch sizes
//! and prints `default ant-v5 fused, batch <B>: <N> updates/s, <M> sampled transitions/s`.
//!
//! FLOPs are counted from the layer shapes, 2 FLOP per multiply-add:
//! * nominal (PyTorch-style, as PyTorch benchmarks count): every layer evaluation the
//!   candle update runs costs 2 per MAC forward, and each one on the differentiated path another
//!   4 per MAC backward (weight and input gradients);
//! * executed: the GEMMs the fused update actually runs (shared observation product, no input
//!   gradients of first layers, no Q backward for the policy, the last coupling layer's nets reused
//!   by the inverse pass).

use std::time::Instant;

use serde::Deserialize;

use agent::{AgentConfig, Batch, Checkpoint, FusedLearner, Learner, Mode};
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

/// Windows measured one at a time, as one [`Rates`].
fn merge(windows: &[Rates]) -> Rates {
    let mut wall: Vec<f64> = windows.iter().map(|r| r.wall.1).collect();
    let mut on_cpu: Vec<f64> = windows.iter().filter_map(|r| r.on_cpu).collect();
    wall.sort_by(f64::total_cmp);
    on_cpu.sort_by(f64::total_cmp);
    let n = wall.len();
    Rates { wall: (wall[0], wall[n / 2], wall[n - 1]), on_cpu: on_cpu.get(on_cpu.len() / 2).copied() }
}

/// One learner's rates; GFLOP/s where the FLOP count is known (the paper-shaped update).
fn print_rate(label: &str, r: Rates, flop: Option<f64>) {
    let (lo, med, hi) = r.wall;
    let on_cpu = r.on_cpu.map_or(String::new(), |c| format!("; {c:7.1}/s per on-CPU second"));
    let gflops = flop.map_or(String::new(), |f| {
        let g = med * f / 1e9;
        format!("  {g:5.1} GFLOP/s = {:4.1}% of peak", 100.0 * g / PEAK_GFLOPS)
    });
    println!("{label:<36} {lo:7.1} / {med:7.1} / {hi:7.1} updates/s{gflops}{on_cpu}");
}

/// The `[agent]` table of a deploy run file, on Ant's dimensions.
fn run_file_agent(file: &str, obs_dim: usize) -> AgentConfig {
    #[derive(Deserialize)]
    struct RunFile {
        #[serde(default)]
        agent: toml::Table,
    }
    let path = format!("{}/../deploy/configs/{file}", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let run: RunFile = toml::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
    let cfg: AgentConfig = run.agent.try_into().unwrap_or_else(|e| panic!("{path} [agent]: {e}"));
    AgentConfig { obs_dim, act_dim: 8, ..cfg }
}

fn main() -> agent::Result<()> {
    let quick = std::env::args().any(|a| a == "--test");
    let (warmup, runs, per_window, acts) = if quick { (2, 1, 2, 10) } else { (100, 7, 200, 20_000) };
    // Both learners use RAYON_NUM_THREADS threads for their matrix products (candle reads it
    // itself, every core when unset; the fused learner is told, 1 when unset).
    let threads: usize = std::env::var("RAYON_NUM_THREADS").ok().and_then(|t| t.parse().ok()).unwrap_or(1);
    println!("agent update bench, {threads} thread(s); peak taken as {PEAK_GFLOPS} GFLOP/s per core");
    println!(
        "updates/s: min / median / max of {runs} windows of {per_window} updates, candle and fused interleaved"
    );
    let configs = [
        ("paper ant-v5", run_file_agent("ant-v5-paper.toml", 105)),
        ("default ant-v5", run_file_agent("ant-v5.toml", 105)),
        ("paper ant-rllab", run_file_agent("ant-rllab.toml", 125)),
    ];
    let mut summary = Vec::new();
    let mut fused_median = Vec::new();
    for (name, cfg) in &configs {
        let paper_shaped = !(cfg.reparameterize || cfg.twin_q || cfg.learn_temperature);
        let (nominal, executed) = flops(cfg, cfg.batch_size);
        if paper_shaped {
            println!(
                "\n{name} (obs {}, batch {}): {:.1} MFLOP nominal per update, {:.1} MFLOP executed by the fused update",
                cfg.obs_dim,
                cfg.batch_size,
                nominal / 1e6,
                executed / 1e6
            );
        } else {
            println!(
                "\n{name} (obs {}, batch {}): reparameterize {}, twin_q {}, learn_temperature {}",
                cfg.obs_dim, cfg.batch_size, cfg.reparameterize, cfg.twin_q, cfg.learn_temperature
            );
        }
        let mut rng = StdRng::seed_from_u64(1);
        let b = batch(cfg, cfg.batch_size, &mut rng);
        let mut candle = Learner::new(cfg.clone(), 1)?;
        let mut fused = FusedLearner::new(cfg.clone(), 1)?.with_threads(threads);
        let mut exact = FusedLearner::new(cfg.clone(), 1)?.with_threads(threads).with_exact_tanh(true);
        for _ in 0..warmup {
            candle.update(&b)?;
            fused.update(&b)?;
            exact.update(&b)?;
        }
        // One window of each per round, so a change in the machine's load hits all three alike.
        let (mut rc, mut rf, mut re) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..runs {
            rc.push(rate(1, per_window, threads == 1, || {
                candle.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
            }));
            rf.push(rate(1, per_window, threads == 1, || {
                fused.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
            }));
            re.push(rate(1, per_window, threads == 1, || {
                exact.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
            }));
        }
        let (rc, rf, re) = (merge(&rc), merge(&rf), merge(&re));
        let flop = |f| if paper_shaped { Some(f) } else { None };
        print_rate("candle (nominal FLOPs)", rc, flop(nominal));
        print_rate("fused (executed FLOPs)", rf, flop(executed));
        print_rate("fused, exact tanh", re, flop(executed));
        summary.push(format!(
            "{name} fused: {:.0} updates/s, candle: {:.0} updates/s, ratio {:.2}",
            rf.wall.1,
            rc.wall.1,
            rf.wall.1 / rc.wall.1
        ));
        fused_median.push(rf.wall.1);

        let mut actor = candle.actor(2)?;
        let obs: Vec<f32> = b.observations[..cfg.obs_dim].to_vec();
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
        let one = batch(cfg, 1, &mut rng);
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
    println!();
    for line in &summary {
        println!("{line}");
    }
    println!("default ant-v5 fused / paper ant-v5 fused: ratio {:.2}", fused_median[1] / fused_median[0]);
    critic_variants(&configs[2].1, threads, (warmup, runs, per_window))?;
    if let Ok(sizes) = std::env::var("UPDATE_BENCH_BATCHES") {
        let sizes: Vec<usize> = sizes.split(',').filter_map(|s| s.trim().parse().ok()).collect();
        batch_sweep(&configs[1].1, &sizes, threads, (warmup, runs, per_window))?;
    }
    if let Ok(path) = std::env::var("UPDATE_BENCH_CHECKPOINT") {
        let default = &configs[1].1;
        trained_checkpoint(&path, default, threads, (warmup, runs, per_window))?;
    }
    Ok(())
}

/// The dissertation's other critics and inputs on the paper's rllab configuration, interleaved with
/// its scalar critic: categorical soft C51 and the dissertation's categorical (candle: the fused
/// learner implements the scalar critic only), and HER's goal-conditioned networks (a 14-d speed
/// goal appended to the observation; fused).
fn critic_variants(
    cfg: &AgentConfig,
    threads: usize,
    (warmup, runs, per_window): (usize, usize, usize),
) -> agent::Result<()> {
    use agent::{AnyLearner, Backend, CategoricalConfig, CategoricalVariant, Critic};
    let categorical = |variant| AgentConfig {
        critic: Critic::Categorical,
        categorical: CategoricalConfig { variant, ..CategoricalConfig::default() },
        ..cfg.clone()
    };
    let variants = [
        ("scalar critic, candle", cfg.clone(), Backend::Candle),
        ("scalar critic, fused", cfg.clone(), Backend::Fused),
        ("categorical soft_c51, candle", categorical(CategoricalVariant::SoftC51), Backend::Candle),
        ("categorical dissertation, candle", categorical(CategoricalVariant::Dissertation), Backend::Candle),
        (
            "HER speed goal (obs + 14), fused",
            AgentConfig { obs_dim: cfg.obs_dim + 14, ..cfg.clone() },
            Backend::Fused,
        ),
    ];
    println!("\ncritic variants on paper ant-rllab (batch {}), interleaved:", cfg.batch_size);
    let mut rng = StdRng::seed_from_u64(3);
    let mut learners = Vec::new();
    for (name, cfg, backend) in variants {
        let b = batch(&cfg, cfg.batch_size, &mut rng);
        let mut learner = AnyLearner::new(cfg, 1, backend)?;
        if let AnyLearner::Fused(f) = learner {
            learner = AnyLearner::Fused(Box::new(f.with_threads(threads)));
        }
        for _ in 0..warmup {
            learner.update(&b)?;
        }
        learners.push((name, learner, b, Vec::new()));
    }
    interleave(&mut learners, runs, per_window, threads == 1, |l, b| l.update(b).map(drop));
    let scalar = merge(&learners[0].3).wall.1;
    for (name, _, _, rates) in &learners {
        let r = merge(rates);
        print_rate(name, r, None);
        println!("    median ratio to the scalar critic on candle: {:.2}", r.wall.1 / scalar);
    }
    Ok(())
}

/// `runs` rounds of one window of `per_window` updates of each learner in turn, so a change in the
/// machine's load hits them all alike; each window's rates go to the learner's list.
fn interleave<T, L>(
    learners: &mut [(T, L, Batch, Vec<Rates>)],
    runs: usize,
    per_window: usize,
    single_thread: bool,
    update: impl Fn(&mut L, &Batch) -> agent::Result<()>,
) {
    for _ in 0..runs {
        for (_, learner, b, rates) in learners.iter_mut() {
            rates.push(rate(1, per_window, single_thread, || {
                update(learner, b).unwrap_or_else(|e| panic!("update failed: {e}"));
            }));
        }
    }
}

/// The default configuration's fused update at other batch sizes, interleaved: the learner's
/// sampled transitions per second, not its updates per second, bound how fast a run learns (batch
/// 64 and 128 learned alike per sampled transition), so this prints both.
fn batch_sweep(
    cfg: &AgentConfig,
    sizes: &[usize],
    threads: usize,
    (warmup, runs, per_window): (usize, usize, usize),
) -> agent::Result<()> {
    let mut learners = Vec::new();
    for &size in sizes {
        let cfg = AgentConfig { batch_size: size, ..cfg.clone() };
        let b = batch(&cfg, size, &mut StdRng::seed_from_u64(5));
        let mut fused = FusedLearner::new(cfg, 1)?.with_threads(threads);
        for _ in 0..warmup {
            fused.update(&b)?;
        }
        learners.push((size, fused, b, Vec::new()));
    }
    interleave(&mut learners, runs, per_window, threads == 1, |l, b| l.update(b).map(drop));
    println!();
    for (size, _, _, rates) in &learners {
        let median = merge(rates).wall.1;
        println!(
            "default ant-v5 fused, batch {size}: {median:.0} updates/s, {:.0} sampled transitions/s",
            median * *size as f64
        );
    }
    Ok(())
}

/// The fused update from a trained checkpoint, with and without flushing subnormals, interleaved.
fn trained_checkpoint(
    path: &str,
    cfg: &AgentConfig,
    threads: usize,
    (warmup, runs, per_window): (usize, usize, usize),
) -> agent::Result<()> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let checkpoint = Checkpoint { step: 0, safetensors: bytes };
    let mut flush = FusedLearner::from_checkpoint(cfg.clone(), &checkpoint)?.with_threads(threads);
    let mut plain = flush.clone().with_flush_denormals(false);
    let b = batch(cfg, cfg.batch_size, &mut StdRng::seed_from_u64(3));
    // Few warm-up updates: the subnormal moments decay to zero within a few hundred of them.
    for _ in 0..warmup.min(5) {
        flush.update(&b)?;
        plain.update(&b)?;
    }
    let (mut rf, mut rp) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        for (learner, rates) in [(&mut flush, &mut rf), (&mut plain, &mut rp)] {
            rates.push(rate(1, per_window, threads == 1, || {
                learner.update(&b).map(drop).unwrap_or_else(|e| panic!("update failed: {e}"));
            }));
        }
    }
    let (rf, rp) = (merge(&rf), merge(&rp));
    println!(
        "trained checkpoint fused, flush: {:.0} updates/s, no flush: {:.0} updates/s, ratio {:.2}",
        rf.wall.1,
        rp.wall.1,
        rf.wall.1 / rp.wall.1
    );
    Ok(())
}
