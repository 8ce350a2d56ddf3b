//! Environments for SAC-LSP: the real MuJoCo Ant and a small fast task, behind one trait.
//!
//! | task | module | semantics |
//! |---|---|---|
//! | `ant-v5` | [`ant_v5`] | Gymnasium Ant-v5 exactly (RK4, dt 0.01 × 5, 105-d observation) |
//! | `ant-rllab` | [`ant_rllab`] | the dissertation's rllab Ant (dt 0.02, actions ×150, 125-d observation) |
//! | `ant-v5-xy` | [`ant_v5`] | Ant-v5 with `exclude_current_positions_from_observation=False` (107-d) |
//! | `inverted-pendulum` | [`pendulum`] | Gymnasium InvertedPendulum-v5, for quick learning checks |
//!
//! [`her`] makes any of them goal-conditioned (hindsight experience replay); [`render`] draws them.
//!
//! Both Ant tasks load one MJCF file, `assets/ant.xml` ([`ant_model`]); [`physics`] owns the MuJoCo
//! model/data pair and the process-wide MuJoCo set-up. Start reading at [`Environment`] and [`Task`].
//!
//! Observations and actions are `f64`. The Ant is chaotic: a 1e-8 change of one control value grows to
//! O(1) within ~100 steps, so reproducing a reference trajectory needs the very same control values; the
//! caller decides how actions are rounded (a policy's `f32` outputs convert exactly). A wrong-length or
//! non-finite action is an [`EnvError`], never a panic.
#![deny(missing_docs)]

pub mod ant_model;
pub mod ant_rllab;
pub mod ant_v5;
mod episode;
mod error;
pub mod her;
mod numpy;
pub mod pendulum;
pub mod physics;
pub mod render;
mod spec;
mod task;

pub use error::EnvError;
pub use run::{Dims, Task};
pub use spec::{EnvSpec, InitState, RewardTerms, Step};
pub use task::make;

/// One simulated task, stepped by one thread. Resets are deterministic given the seed.
pub trait Environment: Send {
    /// Dimensions, bounds and limits of this task.
    fn spec(&self) -> &EnvSpec;

    /// Starts a new episode and returns its first observation. `Some(seed)` restarts the reset-noise
    /// stream from that seed; `None` continues the current stream (Gymnasium's convention).
    fn reset(&mut self, seed: Option<u64>) -> Vec<f64>;

    /// Starts a new episode from an exact physical state (full `qpos` then full `qvel`) instead of a
    /// noisy reset, and returns its first observation.
    fn reset_to(&mut self, state: &InitState) -> Result<Vec<f64>, EnvError>;

    /// Applies one action and advances the simulation by one control step.
    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError>;

    /// The simulation it steps, for drawing it ([`render`]); `None` for a task without one.
    fn physics(&self) -> Option<&physics::Physics> {
        None
    }
}

/// Checks an action's length and finiteness; every task calls this before touching the simulator.
pub(crate) fn check_action(spec: &EnvSpec, action: &[f64]) -> Result<(), EnvError> {
    if action.len() != spec.act_dim {
        return Err(EnvError::ActionDim { expected: spec.act_dim, found: action.len() });
    }
    match action.iter().position(|a| !a.is_finite()) {
        Some(index) => Err(EnvError::NonFiniteAction { index, value: action[index] }),
        None => Ok(()),
    }
}
