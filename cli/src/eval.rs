//! `sac-lsp eval`: evaluates a checkpoint's policy for N episodes (the paper's 200) in one latent
//! mode, writes every episode's return and length as CSV and prints a JSON summary.
//!
//! Episode i resets the task with seed + i and draws its stochastic latents from a stream seeded
//! by (seed, i); the fixed latent is drawn once from the seed. So the figures depend on the seed
//! alone, not on how many threads share the episodes.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::mpsc;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use learner::{Episode, Evaluation, prepare_latent, run_episode};
use serde::Serialize;
use sim::Task;
use sim::her::HerConfig;

use crate::policy::{Latent, Loaded, Policy, PolicyArgs};
use crate::progress::Progress;

/// Options of `sac-lsp eval`.
#[derive(Debug, Args)]
#[command(
    after_help = "Example (the paper's 200 episodes, h = 0, on both cores):\n  sac-lsp eval --checkpoint runs/ID/checkpoints/learner-000000090000.safetensors \\\n      --config deploy/configs/ant-v5.toml --latent zero --threads 2"
)]
pub struct EvalArgs {
    /// The policy.
    #[command(flatten)]
    pub policy: PolicyArgs,
    /// Episodes to run.
    #[arg(long, default_value_t = 200)]
    episodes: u32,
    /// Threads the episodes are spread over (the figures do not depend on it).
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// Per-episode CSV (episode, return, length); default: beside the checkpoint, named after it,
    /// the mode and the seed.
    #[arg(long)]
    csv: Option<PathBuf>,
}

/// Runs the evaluation.
pub fn run(args: &EvalArgs) -> Result<()> {
    if args.episodes == 0 || args.threads == 0 {
        bail!("--episodes and --threads must be at least 1");
    }
    let Loaded { task, her, policy } = args.policy.load()?;
    let episodes = run_episodes(args, task, &her, &policy)?;
    let (checkpoint, latent, seed) = (&args.policy.checkpoint, args.policy.latent, args.policy.seed);
    let csv = args.csv.clone().unwrap_or_else(|| default_csv(checkpoint, latent, seed));
    write_csv(&csv, &episodes)?;
    println!("{}", serde_json::to_string(&Summary::new(args, task, &policy, &episodes, &csv))?);
    Ok(())
}

/// Runs every episode, spread over the threads, and returns them in episode order.
fn run_episodes(args: &EvalArgs, task: Task, her: &HerConfig, policy: &Policy) -> Result<Vec<Episode>> {
    let mode = args.policy.latent.mode();
    // The fixed latent, drawn once from the seed and shared by every thread.
    let mut first = policy.actor(args.policy.seed)?;
    let act_mode = prepare_latent(&mut first, mode);
    let latent = first.fixed_latent().to_vec();
    let (sender, receiver) = mpsc::channel::<Result<(u32, Episode)>>();
    let n = args.episodes;
    let threads = args.threads.min(n as usize);
    std::thread::scope(|scope| {
        for thread in 0..threads {
            let sender = sender.clone();
            let latent = &latent;
            scope.spawn(move || {
                let work = || -> Result<()> {
                    let mut env = sim::her::make(her, task, args.policy.seed)?;
                    let mut actor = policy.actor(args.policy.seed)?;
                    actor.load(&policy.snapshot)?;
                    actor.set_fixed_latent(latent)?;
                    for i in (thread as u32..n).step_by(threads) {
                        let seed = args.policy.seed.wrapping_add(u64::from(i));
                        // Another stream than the fixed latent's (drawn from the seed itself).
                        actor.reseed(seed ^ 0x5eed_0000_0000_0000);
                        let episode = run_episode(&mut actor, env.as_mut(), act_mode, Some(seed))?;
                        if sender.send(Ok((i, episode))).is_err() {
                            break;
                        }
                    }
                    Ok(())
                };
                if let Err(error) = work() {
                    let _ = sender.send(Err(error));
                }
            });
        }
        drop(sender);
        collect(receiver, n)
    })
}

/// Gathers the episodes as they finish, showing progress on stderr.
fn collect(receiver: mpsc::Receiver<Result<(u32, Episode)>>, n: u32) -> Result<Vec<Episode>> {
    let mut episodes: Vec<Option<Episode>> = vec![None; n as usize];
    let (mut done, mut sum) = (0u32, 0.0);
    let mut progress = Progress::new("episodes", u64::from(n));
    for message in receiver {
        let (i, episode) = message?;
        episodes[i as usize] = Some(episode);
        done += 1;
        sum += episode.episode_return;
        progress.inc(&format!("mean return so far {:.1}", sum / f64::from(done)));
    }
    progress.finish();
    episodes
        .into_iter()
        .enumerate()
        .map(|(i, e)| e.with_context(|| format!("episode {i} did not finish")))
        .collect()
}

fn default_csv(checkpoint: &Path, latent: Latent, seed: u64) -> PathBuf {
    let stem = checkpoint.file_stem().and_then(|s| s.to_str()).unwrap_or("checkpoint");
    let mode = latent.to_possible_value().map_or_else(String::new, |v| v.get_name().to_string());
    checkpoint.with_file_name(format!("{stem}.eval-{mode}-seed{seed}.csv"))
}

fn write_csv(path: &Path, episodes: &[Episode]) -> Result<()> {
    let mut out = String::from("episode,return,length,goal_reached\n");
    for (i, e) in episodes.iter().enumerate() {
        let reached = e.goal_reached.map_or(String::new(), |r| u8::from(r).to_string());
        out.push_str(&format!("{i},{},{},{reached}\n", e.episode_return, e.length));
    }
    let mut file = std::fs::File::create(path).with_context(|| format!("writing {}", path.display()))?;
    file.write_all(out.as_bytes())?;
    Ok(())
}

/// The JSON summary: mean, standard deviation (population), standard error, min, max, median and
/// mean length of the returns, with what was evaluated and how.
#[derive(Debug, Serialize)]
struct Summary {
    checkpoint: String,
    learner_step: Option<u64>,
    frozen_levels: usize,
    task: &'static str,
    mode: &'static str,
    episodes: u32,
    seed: u64,
    mean: f64,
    std: f64,
    stderr: f64,
    min: f64,
    max: f64,
    median: f64,
    mean_length: f64,
    /// With HER: the fraction of episodes that reached their goal at some step.
    goal_success: Option<f64>,
    csv: String,
}

impl Summary {
    fn new(args: &EvalArgs, task: Task, policy: &Policy, episodes: &[Episode], csv: &Path) -> Self {
        let Evaluation { mean_return: mean, std_return: std, mean_length, goal_success } =
            Evaluation::of(episodes);
        let mut sorted: Vec<f64> = episodes.iter().map(|e| e.episode_return).collect();
        sorted.sort_by(f64::total_cmp);
        let mid = sorted.len() / 2;
        let median = if sorted.len() % 2 == 1 { sorted[mid] } else { (sorted[mid - 1] + sorted[mid]) / 2.0 };
        Self {
            checkpoint: args.policy.checkpoint.display().to_string(),
            learner_step: policy.learner_step,
            frozen_levels: policy.frozen.len(),
            task: task.name(),
            mode: args.policy.latent.mode().name(),
            episodes: args.episodes,
            seed: args.policy.seed,
            mean,
            std,
            stderr: std / (sorted.len() as f64).sqrt(),
            min: sorted[0],
            max: sorted[sorted.len() - 1],
            median,
            mean_length,
            goal_success,
            csv: csv.display().to_string(),
        }
    }
}

#[cfg(test)]
mod tests {
    use agent::{AgentConfig, Learner, PolicyStack};

    use super::*;
    use crate::policy::tests::{checkpoint, policy_args};
    use crate::policy::{read_policy, read_run_file};

    /// `run_episodes` on the pendulum without goals.
    fn pendulum_episodes(args: &EvalArgs, policy: &Policy) -> Vec<Episode> {
        run_episodes(args, Task::InvertedPendulum, &HerConfig::default(), policy).unwrap()
    }

    fn args(checkpoint: &Path, latent: Latent, threads: usize) -> EvalArgs {
        EvalArgs { policy: policy_args(checkpoint, latent), episodes: 6, threads, csv: None }
    }

    #[test]
    fn the_figures_depend_on_the_seed_not_the_threads() {
        let path = checkpoint("threads", true);
        let policy = read_policy(&path, None).unwrap();
        assert_eq!((policy.config.obs_dim, policy.config.act_dim, policy.config.twin_q), (4, 1, true));
        assert_eq!(policy.learner_step, Some(0));
        for latent in [Latent::Fixed, Latent::Zero, Latent::Stochastic] {
            let one = pendulum_episodes(&args(&path, latent, 1), &policy);
            let three = pendulum_episodes(&args(&path, latent, 3), &policy);
            assert_eq!(one, three, "{latent:?}");
            assert_eq!(one.len(), 6);
            assert!(one.iter().all(|e| e.length >= 1 && e.episode_return.is_finite()));
        }
        // The whole command writes the CSV beside the checkpoint.
        run(&args(&path, Latent::Zero, 2)).unwrap();
        let csv = std::fs::read_to_string(default_csv(&path, Latent::Zero, 11)).unwrap();
        assert_eq!(csv.lines().count(), 7);
        assert!(csv.starts_with("episode,return,length,goal_reached\n0,"));
    }

    #[test]
    fn bad_input_is_one_line_naming_what_is_wrong() {
        let path = checkpoint("bad", false);
        let mut on_ant = args(&path, Latent::Zero, 1);
        on_ant.policy.task = Some(Task::AntV5);
        let err = run(&on_ant).unwrap_err().to_string();
        assert!(err.contains("take 4 observation and 1 action values, but ant-v5 has 105 and 8"), "{err}");
        let junk = path.with_file_name("junk.safetensors");
        std::fs::write(&junk, b"not a checkpoint").unwrap();
        let err = run(&args(&junk, Latent::Zero, 1)).unwrap_err().to_string();
        assert!(err.contains("is not a safetensors file"), "{err}");
        let missing = path.with_file_name("missing.safetensors");
        assert!(format!("{:#}", run(&args(&missing, Latent::Zero, 1)).unwrap_err()).contains("reading"));
        let none = EvalArgs { episodes: 0, ..args(&path, Latent::Zero, 1) };
        assert!(run(&none).unwrap_err().to_string().contains("--episodes"));
    }

    /// A pendulum level above another, as a checkpoint.
    fn high_level() -> agent::Checkpoint {
        let cfg = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            coupling_hidden: vec![4],
            ..AgentConfig::for_task(4, 1).level_above()
        };
        Learner::new(cfg, 8).unwrap().checkpoint().unwrap()
    }

    /// A 2-level checkpoint for the pendulum: a level trained on top of `low`, frozen inside it.
    fn hierarchy_checkpoint(name: &str, low: &Path) -> PathBuf {
        let stack = PolicyStack::from_weights(&[std::fs::read(low).unwrap()]).unwrap();
        let path = low.with_file_name(format!("{name}.safetensors"));
        std::fs::write(&path, stack.embed(&high_level()).unwrap().safetensors).unwrap();
        path
    }

    #[test]
    fn a_hierarchy_checkpoint_evaluates_through_its_frozen_levels() {
        let low = checkpoint("hierarchy", false);
        let path = hierarchy_checkpoint("two-level", &low);
        let policy = read_policy(&path, None).unwrap();
        assert_eq!(policy.frozen.len(), 1);
        assert!(!policy.config.squash && !policy.config.embedding_output_relu, "the level-above settings");
        let one = pendulum_episodes(&args(&path, Latent::Fixed, 1), &policy);
        let two = pendulum_episodes(&args(&path, Latent::Fixed, 2), &policy);
        assert_eq!(one, two);
        assert!(one.iter().all(|e| e.length >= 1 && e.episode_return.is_finite()));
        // A plain top-level file with the frozen level named by a run file evaluates the same.
        let plain = low.with_file_name("top-only.safetensors");
        std::fs::write(&plain, high_level().safetensors).unwrap();
        let run_file = low.with_file_name("run.toml");
        std::fs::write(&run_file, format!("[hierarchy]\nlevels = [{:?}]\n", low.display().to_string()))
            .unwrap();
        let named = read_policy(&plain, Some(&read_run_file(&run_file).unwrap())).unwrap();
        let again = pendulum_episodes(&args(&plain, Latent::Fixed, 1), &named);
        assert_eq!(one, again);
    }

    #[test]
    fn a_stack_that_does_not_chain_is_named() {
        // A frozen level for another task (6 observations) under a pendulum level.
        let dir = std::env::temp_dir().join(format!("sac-lsp-eval-chain-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let other = AgentConfig {
            critic_hidden: vec![8],
            embedding_layers: vec![8, 2],
            ..AgentConfig::for_task(6, 1)
        };
        let low = dir.join("low.safetensors");
        std::fs::write(&low, Learner::new(other, 1).unwrap().checkpoint().unwrap().safetensors).unwrap();
        let path = hierarchy_checkpoint("mismatched", &low);
        let err = format!("{:#}", run(&args(&path, Latent::Zero, 1)).unwrap_err());
        assert!(
            err.contains("mismatched.safetensors") && err.contains("top frozen level expects (obs 6"),
            "{err}"
        );
        assert_eq!(err.lines().count(), 1, "{err}");
    }
}
