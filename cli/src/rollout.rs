//! `sac-lsp rollout`: steps a task with given actions and writes the trajectory, so it can be compared
//! with another implementation of the same task (e.g. Gymnasium) value for value.

use std::io::{BufWriter, Write};
use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use sim::{InitState, Task};

use crate::csv;

/// Options of `sac-lsp rollout`.
#[derive(Debug, Args)]
#[command(
    after_help = "Example (the check against Gymnasium in tests/reference/):\n  sac-lsp rollout --task ant-v5 --actions actions.csv --seed 0 --out trajectory.csv"
)]
pub struct RolloutArgs {
    /// Task to step: ant-v5, ant-rllab or inverted-pendulum.
    #[arg(long)]
    task: Task,
    /// Actions, one CSV row per step (a header row is allowed).
    #[arg(long)]
    actions: PathBuf,
    /// Start from this exact state: one CSV row holding the full qpos then the full qvel.
    #[arg(long, conflicts_with = "seed")]
    init_state: Option<PathBuf>,
    /// Start from a seeded noisy reset instead (default seed 0).
    #[arg(long)]
    seed: Option<u64>,
    /// How the action values reach the simulator. The Ant is chaotic, so the controls must be
    /// bit-identical to the reference's: `f64` uses the file's values as written (what Gymnasium
    /// simulates when given the float64 array it read from the file); `f32` rounds them to float32
    /// first (what it simulates when the array is cast to the action space's dtype).
    #[arg(long, value_enum, default_value_t = ActionPrecision::F64)]
    action_dtype: ActionPrecision,
    /// Stop after the first terminated or truncated step instead of stepping through every action
    /// (Gymnasium keeps stepping when the caller does not reset, and so does this by default).
    #[arg(long)]
    stop_at_done: bool,
    /// Output file (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Precision of the actions handed to the simulator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ActionPrecision {
    /// As written in the file.
    F64,
    /// Rounded to float32.
    F32,
}

/// Runs the rollout.
pub fn run(args: &RolloutArgs) -> Result<()> {
    let mut env = sim::make(args.task, args.seed.unwrap_or(0))?;
    let spec = env.spec().clone();
    let mut actions = csv::read_rows(&args.actions)?;
    if let Some(row) = actions.iter().position(|row| row.len() != spec.act_dim) {
        bail!(
            "actions row {} has {} values; {} takes {}",
            row + 1,
            actions[row].len(),
            spec.name,
            spec.act_dim
        );
    }
    if args.action_dtype == ActionPrecision::F32 {
        actions.iter_mut().flatten().for_each(|a| *a = f64::from(*a as f32));
    }

    let first_observation = match &args.init_state {
        Some(path) => {
            let rows = csv::read_rows(path)?;
            let [row] = rows.as_slice() else {
                bail!("{} must hold exactly one row (qpos then qvel), found {}", path.display(), rows.len());
            };
            env.reset_to(&InitState::from_row(row, spec.nq, spec.nv)?)?
        }
        None => env.reset(args.seed.or(Some(0))),
    };

    let sink: Box<dyn Write> = match &args.out {
        Some(path) => {
            Box::new(std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?)
        }
        None => Box::new(std::io::stdout().lock()),
    };
    let mut out = BufWriter::new(sink);
    write_header(&mut out, spec.obs_dim, spec.reward_terms)?;
    // Row t = 0 is the reset observation; it has no reward, so its reward and terms are written as 0.
    let no_terms = vec![0.0; spec.reward_terms.len()];
    let reset_row = Row {
        t: 0,
        observation: &first_observation,
        reward: 0.0,
        terminated: false,
        truncated: false,
        terms: &no_terms,
    };
    reset_row.write(&mut out)?;
    for (t, action) in actions.iter().enumerate() {
        let step = env.step(action).with_context(|| format!("step {}", t + 1))?;
        Row {
            t: t + 1,
            observation: &step.observation,
            reward: step.reward,
            terminated: step.terminated,
            truncated: step.truncated,
            terms: step.terms.values(),
        }
        .write(&mut out)?;
        if (step.terminated || step.truncated) && args.stop_at_done {
            break;
        }
    }
    out.flush()?;
    Ok(())
}

fn write_header(out: &mut impl Write, obs_dim: usize, terms: &[&str]) -> Result<()> {
    let mut columns = vec!["t".to_string()];
    columns.extend((0..obs_dim).map(|i| format!("obs_{i}")));
    columns.extend(["reward", "terminated", "truncated"].map(String::from));
    columns.extend(terms.iter().map(|t| t.to_string()));
    writeln!(out, "{}", columns.join(","))?;
    Ok(())
}

/// One line of the trajectory CSV.
struct Row<'a> {
    t: usize,
    observation: &'a [f64],
    reward: f64,
    terminated: bool,
    truncated: bool,
    terms: &'a [f64],
}

impl Row<'_> {
    /// Floats use Rust's shortest round-trip formatting, so parsing them back gives the same f64.
    fn write(&self, out: &mut impl Write) -> Result<()> {
        write!(out, "{}", self.t)?;
        for v in self.observation {
            write!(out, ",{v:?}")?;
        }
        write!(out, ",{:?},{},{}", self.reward, u8::from(self.terminated), u8::from(self.truncated))?;
        for v in self.terms {
            write!(out, ",{v:?}")?;
        }
        writeln!(out)?;
        Ok(())
    }
}
