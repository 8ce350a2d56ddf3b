use std::fmt;
use std::str::FromStr;

use crate::{EnvError, Environment, ant_rllab::AntRllab, ant_v5::AntV5, pendulum::InvertedPendulum};

/// A task's observation and action widths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// Observation values.
    pub obs_dim: usize,
    /// Action values.
    pub act_dim: usize,
}

/// The tasks this crate simulates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Task {
    /// Gymnasium Ant-v5.
    AntV5,
    /// Gymnasium Ant-v5 with `exclude_current_positions_from_observation=False` (107-d).
    AntV5Xy,
    /// The dissertation's rllab Ant.
    AntRllab,
    /// Gymnasium InvertedPendulum-v5.
    InvertedPendulum,
}

impl Task {
    /// Every task, in a stable order.
    pub const ALL: [Task; 4] = [Task::AntV5, Task::AntV5Xy, Task::AntRllab, Task::InvertedPendulum];

    /// The task's name on the command line and in configs.
    pub fn name(self) -> &'static str {
        match self {
            Task::AntV5 => "ant-v5",
            Task::AntV5Xy => "ant-v5-xy",
            Task::AntRllab => "ant-rllab",
            Task::InvertedPendulum => "inverted-pendulum",
        }
    }

    /// The widths of its observation and action, without loading its model: what configurations
    /// size networks and buffers from (a test holds them equal to the built environment's).
    pub fn dims(self) -> Dims {
        let (obs_dim, act_dim) = match self {
            // qpos without x, y (13) + qvel (14) + clipped contact forces of 13 bodies (78).
            Task::AntV5 => (105, 8),
            // ... with x, y.
            Task::AntV5Xy => (107, 8),
            // qpos (15) + qvel (14) + contact forces of 14 bodies (84) + torso rotation (9) + com (3).
            Task::AntRllab => (125, 8),
            // cart and pole position and velocity.
            Task::InvertedPendulum => (4, 1),
        };
        Dims { obs_dim, act_dim }
    }

    /// Builds a fresh environment whose reset-noise stream starts at `seed`.
    pub fn make(self, seed: u64) -> Result<Box<dyn Environment>, EnvError> {
        Ok(match self {
            Task::AntV5 => Box::new(AntV5::new(seed)?),
            Task::AntV5Xy => Box::new(AntV5::with_positions(seed, true)?),
            Task::AntRllab => Box::new(AntRllab::new(seed)?),
            Task::InvertedPendulum => Box::new(InvertedPendulum::new(seed)?),
        })
    }
}

impl fmt::Display for Task {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Task {
    type Err = EnvError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Task::ALL.into_iter().find(|t| t.name() == s).ok_or_else(|| EnvError::UnknownTask(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dims_are_the_built_environments() {
        for task in Task::ALL {
            let mut env = task.make(0).unwrap();
            let spec = env.spec().clone();
            assert_eq!(task.dims(), Dims { obs_dim: spec.obs_dim, act_dim: spec.act_dim }, "{task}");
            assert_eq!(env.reset(Some(0)).len(), spec.obs_dim, "{task}");
        }
    }
}
