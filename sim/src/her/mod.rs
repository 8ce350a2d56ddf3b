//! Hindsight experience replay (the dissertation's §3.4 and §4.4; `docs/sac-lsp.md` §14), sans-IO:
//!
//! | file | what |
//! |---|---|
//! | `config.rs` | [`make`], [`hindsight`]: what the `[her]` table ([`HerConfig`], `run`'s) builds |
//! | `env.rs` | [`GoalEnv`]: a task whose observation ends with the episode's goal |
//! | `relabel.rs` | [`Hindsight`]: the stored reward, and the "future" relabelling at an episode's end |
//!
//! A goal is a target for a slice of the observation: the joint velocities qvel (a **speed** goal,
//! the dissertation code's) or the torso's x, y (a **position** goal). [`make`] builds
//! the task every role steps, so the networks' input (observation ++ goal) follows from it.
//! The environment's own reward is what every evaluation reports (the dissertation's Table 5.2);
//! the goal-shaped reward is what the learner trains on, and [`GoalStatus`] on each step says
//! whether the goal was reached.

mod config;
mod env;
mod relabel;

pub use config::{hindsight, make};
pub use env::{GoalEnv, GoalStatus};
pub use relabel::{Hindsight, Relabelled};
pub use run::{GoalKind, GoalReward, HerConfig};
