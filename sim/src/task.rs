//! Building a task's environment. The tasks themselves ([`Task`]: names and widths) are `run`'s, so
//! that roles which never simulate need not link MuJoCo.

use run::Task;

use crate::{EnvError, Environment, ant_rllab::AntRllab, ant_v5::AntV5, pendulum::InvertedPendulum};

/// Builds a fresh environment of `task` whose reset-noise stream starts at `seed`.
pub fn make(task: Task, seed: u64) -> Result<Box<dyn Environment>, EnvError> {
    Ok(match task {
        Task::AntV5 => Box::new(AntV5::new(seed)?),
        Task::AntV5Xy => Box::new(AntV5::with_positions(seed, true)?),
        Task::AntRllab => Box::new(AntRllab::new(seed)?),
        Task::InvertedPendulum => Box::new(InvertedPendulum::new(seed)?),
    })
}

#[cfg(test)]
mod tests {
    use run::Dims;

    use super::*;

    #[test]
    fn dims_are_the_built_environments() {
        for task in Task::ALL {
            let mut env = make(task, 0).unwrap();
            let spec = env.spec().clone();
            assert_eq!(task.dims(), Dims { obs_dim: spec.obs_dim, act_dim: spec.act_dim }, "{task}");
            assert_eq!(env.reset(Some(0)).len(), spec.obs_dim, "{task}");
        }
    }
}
