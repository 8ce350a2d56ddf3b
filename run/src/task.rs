use std::fmt;
use std::str::FromStr;

/// A task's observation and action widths.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dims {
    /// Observation values.
    pub obs_dim: usize,
    /// Action values.
    pub act_dim: usize,
}

/// The tasks `sim` simulates (`sim::make` builds one); named here so that every role can size its
/// networks and buffers from a run file without loading MuJoCo.
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
    /// size networks and buffers from (a test of `sim` holds them equal to the built environment's).
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
}

impl fmt::Display for Task {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A task name that names no task.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown task {0:?} (known: ant-v5, ant-v5-xy, ant-rllab, inverted-pendulum)")]
pub struct UnknownTask(pub String);

impl FromStr for Task {
    type Err = UnknownTask;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Task::ALL.into_iter().find(|t| t.name() == s).ok_or_else(|| UnknownTask(s.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_are_refused() {
        for task in Task::ALL {
            assert_eq!(task.name().parse::<Task>(), Ok(task));
        }
        assert_eq!("ant-v4".parse::<Task>(), Err(UnknownTask("ant-v4".into())));
    }
}
