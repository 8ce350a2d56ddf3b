//! What the `[her]` table ([`HerConfig`], `run::her`) builds here: the goal-conditioned task and the
//! relabelling.

use run::{HerConfig, Task};

use super::{GoalEnv, Hindsight};
use crate::{EnvError, Environment};

/// The task every role of a run steps: `task` itself, or with HER on, `task` with the episode's
/// goal appended to its observation ([`GoalEnv`]). A goal the task has no slice for is an error.
pub fn make(her: &HerConfig, task: Task, seed: u64) -> Result<Box<dyn Environment>, EnvError> {
    let env = crate::make(task, seed)?;
    if !her.enabled() {
        return Ok(env);
    }
    let slice = her.slice(task).map_err(EnvError::Config)?;
    Ok(Box::new(GoalEnv::new(env, slice, her.effective_goal_range(), her.effective_threshold(), seed)))
}

/// The relabelling of a run on `task` (`None` with HER off); draws start from `seed`.
pub fn hindsight(her: &HerConfig, task: Task, seed: u64) -> Option<Hindsight> {
    her.enabled().then(|| Hindsight::new(her, her.goal_dim(task), seed))
}

/// L2 distance between two goals.
pub(crate) fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum::<f64>().sqrt()
}

#[cfg(test)]
mod tests {
    use run::{GoalKind, GoalReward};

    use super::*;

    fn her(goal: GoalKind, reward: GoalReward) -> HerConfig {
        HerConfig { goal, reward, ..HerConfig::default() }
    }

    #[test]
    fn off_the_task_is_unchanged() {
        assert_eq!(make(&HerConfig::default(), Task::AntV5, 0).unwrap().spec().obs_dim, 105);
    }

    #[test]
    fn the_goal_slices_are_qvel_and_the_torso_position() {
        // ant-v5-xy's observation is qpos ++ qvel ++ ...: compare with the full physical state.
        for task in [Task::AntRllab, Task::AntV5Xy] {
            let mut env = crate::make(task, 3).unwrap();
            let obs = env.reset(Some(3));
            let state = crate::InitState { qpos: obs[..15].to_vec(), qvel: obs[15..29].to_vec() };
            let again = env.reset_to(&state).unwrap();
            let speed = her(GoalKind::Speed, GoalReward::Binary).slice(task).unwrap();
            assert_eq!(&again[speed], &state.qvel[..], "{task}");
            let position = her(GoalKind::Position, GoalReward::Binary).slice(task).unwrap();
            assert_eq!(&again[position], &state.qpos[..2], "{task}");
        }
    }

    #[test]
    fn dims_are_the_goal_conditioned_environments() {
        for goal in [GoalKind::None, GoalKind::Speed, GoalKind::Position] {
            let her = her(goal, GoalReward::Binary);
            for task in Task::ALL.into_iter().filter(|t| her.validate(*t, 1).is_ok()) {
                let spec = make(&her, task, 0).unwrap().spec().clone();
                assert_eq!(her.dims(task), run::Dims { obs_dim: spec.obs_dim, act_dim: spec.act_dim });
            }
        }
    }
}
