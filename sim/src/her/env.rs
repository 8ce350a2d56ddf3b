//! [`GoalEnv`]: a task whose observation ends with the episode's goal.

use std::ops::Range;

use rand::{Rng, SeedableRng, rngs::StdRng};

use crate::{EnvError, EnvSpec, Environment, InitState, Step};

use super::config::distance;

/// Where a step got relative to its episode's goal.
#[derive(Clone, Debug, PartialEq)]
pub struct GoalStatus {
    /// The achieved goal: the goal's slice of the step's observation.
    pub achieved: Vec<f64>,
    /// L2 distance from the achieved goal to the episode's goal.
    pub distance: f64,
    /// `distance` is below the threshold.
    pub reached: bool,
}

/// A task whose observation is its own followed by the episode's goal g. Each reset draws
/// g = achieved(first observation) + U(-range, range) per component (`sac-hind`'s goal_type 0,
/// seed-impl §2.4). Rewards stay the task's own; each [`Step::goal`] says how close the step came.
pub struct GoalEnv {
    inner: Box<dyn Environment>,
    spec: EnvSpec,
    slice: Range<usize>,
    range: f64,
    threshold: f64,
    rng: StdRng,
    goal: Vec<f64>,
}

impl std::fmt::Debug for GoalEnv {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GoalEnv").field("spec", &self.spec).field("goal", &self.goal).finish_non_exhaustive()
    }
}

/// Goal draws get their own stream, apart from the task's reset noise.
const GOAL_STREAM: u64 = 0x6f61_6c73_4845_5221;

impl GoalEnv {
    /// `inner` with goals for observation slice `slice`, drawn within `range`, reached within
    /// `threshold`; goal draws start from `seed`.
    pub fn new(
        inner: Box<dyn Environment>,
        slice: Range<usize>,
        range: f64,
        threshold: f64,
        seed: u64,
    ) -> Self {
        let mut spec = inner.spec().clone();
        spec.obs_dim += slice.len();
        let goal = vec![0.0; slice.len()];
        Self { inner, spec, slice, range, threshold, rng: StdRng::seed_from_u64(seed ^ GOAL_STREAM), goal }
    }

    /// The current episode's goal.
    pub fn goal(&self) -> &[f64] {
        &self.goal
    }

    /// Replaces the episode's goal (evaluation with chosen goals, tests).
    pub fn set_goal(&mut self, goal: &[f64]) -> Result<(), EnvError> {
        if goal.len() != self.goal.len() || goal.iter().any(|g| !g.is_finite()) {
            return Err(EnvError::Config(format!("a goal needs {} finite values", self.goal.len())));
        }
        self.goal.copy_from_slice(goal);
        Ok(())
    }

    fn start(&mut self, mut observation: Vec<f64>) -> Vec<f64> {
        let range = self.range;
        self.goal = observation[self.slice.clone()]
            .iter()
            .map(|a| a + if range > 0.0 { self.rng.random_range(-range..range) } else { 0.0 })
            .collect();
        observation.extend_from_slice(&self.goal);
        observation
    }
}

impl Environment for GoalEnv {
    fn spec(&self) -> &EnvSpec {
        &self.spec
    }

    fn physics(&self) -> Option<&crate::physics::Physics> {
        self.inner.physics()
    }

    fn reset(&mut self, seed: Option<u64>) -> Vec<f64> {
        if let Some(seed) = seed {
            self.rng = StdRng::seed_from_u64(seed ^ GOAL_STREAM);
        }
        let observation = self.inner.reset(seed);
        self.start(observation)
    }

    fn reset_to(&mut self, state: &InitState) -> Result<Vec<f64>, EnvError> {
        let observation = self.inner.reset_to(state)?;
        Ok(self.start(observation))
    }

    fn step(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        let mut step = self.inner.step(action)?;
        let achieved = step.observation[self.slice.clone()].to_vec();
        let distance = distance(&achieved, &self.goal);
        step.goal = Some(GoalStatus { achieved, distance, reached: distance < self.threshold });
        step.observation.extend_from_slice(&self.goal);
        Ok(step)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Task;
    use crate::her::{GoalKind, HerConfig};

    #[test]
    fn the_goal_follows_the_observation_and_each_step_reports_its_distance() {
        let her = HerConfig { goal: GoalKind::Speed, ..HerConfig::default() };
        let mut env = crate::her::make(&her, Task::AntRllab, 5).unwrap();
        assert_eq!(env.spec().obs_dim, 125 + 14);
        let first = env.reset(Some(5));
        let goal = first[125..].to_vec();
        // Within the range of the achieved qvel at reset.
        assert!(goal.iter().zip(&first[15..29]).all(|(g, a)| (g - a).abs() <= 15.0));
        assert!(goal.iter().zip(&first[15..29]).any(|(g, a)| (g - a).abs() > 1.0));
        let step = env.step(&[0.1; 8]).unwrap();
        assert_eq!(&step.observation[125..], &goal[..], "the goal holds for the episode");
        let status = step.goal.unwrap();
        assert_eq!(status.achieved, step.observation[15..29].to_vec());
        assert!((status.distance - distance(&status.achieved, &goal)).abs() < 1e-12);
        assert_eq!(status.reached, status.distance < 3.0);
        // The same seed draws the same goal; the next episode another.
        assert_eq!(env.reset(Some(5))[125..], goal[..]);
        assert_ne!(env.reset(None)[125..], goal[..]);
    }
}
