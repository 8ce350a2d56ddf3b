//! The `[her]` table: which goal, which reward, how many relabelled goals. The environments and the
//! relabelling it configures are `sim::her`'s.

use std::ops::Range;

use serde::{Deserialize, Serialize};

use crate::{Dims, Task};

/// What a goal is a target for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalKind {
    /// No goal: HER is off (the default).
    #[default]
    None,
    /// The joint velocities qvel (all nv of them), as `sac-hind` defines its goal (seed-impl §2.4:
    /// the qvel slice of the rllab observation, 14 values).
    Speed,
    /// The torso's x, y (the dissertation's position goal, §4.4; not in its code). Needs a task whose
    /// observation has them: `ant-rllab` or `ant-v5-xy`.
    Position,
}

/// How the stored reward is made from the environment's reward r_env and the goal. "Reached"
/// means the L2 distance between the achieved and the desired goal is below the threshold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GoalReward {
    /// r = 0 if reached, else -1: UVFA's binary reward as `sac-hind` codes it (her_type 0; the
    /// dissertation's text has the signs swapped, seed-impl §2.5 item 7).
    #[default]
    Binary,
    /// r = r_env + r_binary: the dissertation's sum-augmented reward (Eq. 3.3; not in its code).
    Sum,
    /// r = r_env (1 + bonus) if reached, else r_env: the proportionally augmented reward as the code
    /// has it (her_type 2, bonus 0.5; the text's Eq. 3.4 writes r_env + r_g 0.1 r_env).
    Proportional,
    /// r = r_env - weight * distance: the code's distance-proportional reward (her_type 3, weight 0.05).
    Distance,
}

/// The `[her]` table. Defaults: HER off; when on, the dissertation's k = 4 "future" goals per
/// transition, its thresholds (3.0 for speed, 10.0 for position; §4.4) and the code's goal ranges
/// and reward constants.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HerConfig {
    /// The goal. Default `none` (HER off).
    pub goal: GoalKind,
    /// The stored reward. Default `binary`.
    pub reward: GoalReward,
    /// Relabelled copies of each transition, each with a goal achieved later in its episode
    /// ("future" strategy). Default 4.
    pub k: usize,
    /// A goal is reached within this L2 distance. Default: 3.0 (speed), 10.0 (position).
    pub threshold: Option<f64>,
    /// An episode's goal is the achieved goal at reset plus U(-range, range) per component.
    /// Default: 15 (speed, the code's goal_type 0), 20 (position: the code has none; twice the
    /// threshold, about what a trained Ant covers in an episode).
    pub goal_range: Option<f64>,
    /// The proportional reward's bonus fraction. Default 0.5 (the code's).
    pub proportional_bonus: f64,
    /// The distance reward's weight. Default 0.05 (the code's).
    pub distance_weight: f64,
}

impl Default for HerConfig {
    fn default() -> Self {
        Self {
            goal: GoalKind::None,
            reward: GoalReward::Binary,
            k: 4,
            threshold: None,
            goal_range: None,
            proportional_bonus: 0.5,
            distance_weight: 0.05,
        }
    }
}

impl HerConfig {
    /// Whether HER is on.
    pub fn enabled(&self) -> bool {
        self.goal != GoalKind::None
    }

    /// The threshold in use.
    pub fn effective_threshold(&self) -> f64 {
        self.threshold.unwrap_or(if self.goal == GoalKind::Position { 10.0 } else { 3.0 })
    }

    /// The goal range in use.
    pub fn effective_goal_range(&self) -> f64 {
        self.goal_range.unwrap_or(if self.goal == GoalKind::Position { 20.0 } else { 15.0 })
    }

    /// Where `task`'s observation holds this goal's achieved value.
    pub fn slice(&self, task: Task) -> Result<Range<usize>, String> {
        let slice = match (self.goal, task) {
            (GoalKind::None, _) => Some(0..0),
            // rllab: qpos 15 | qvel 14 | ...; ant-v5-xy: the same start; ant-v5: qpos[2:] 13 | qvel 14.
            (GoalKind::Speed, Task::AntRllab | Task::AntV5Xy) => Some(15..29),
            (GoalKind::Speed, Task::AntV5) => Some(13..27),
            (GoalKind::Position, Task::AntRllab | Task::AntV5Xy) => Some(0..2),
            (GoalKind::Position, Task::AntV5) => None,
            // Cart position, pole angle | their velocities.
            (GoalKind::Speed, Task::InvertedPendulum) => Some(2..4),
            (GoalKind::Position, Task::InvertedPendulum) => Some(0..1),
        };
        slice.ok_or_else(|| {
            format!("[her] goal = \"position\" needs the torso's x, y in the observation: use task ant-v5-xy, not {task}")
        })
    }

    /// Checks every field against `task` and the agent's n-step length; the error names the first
    /// offending one.
    pub fn validate(&self, task: Task, n_step: usize) -> Result<(), String> {
        if !self.enabled() {
            return Ok(());
        }
        self.slice(task)?;
        if n_step != 1 {
            // A relabelled n-step transition would need its n rewards recomputed for the new goal.
            return Err(format!("[her] needs [agent] n_step = 1, got {n_step}"));
        }
        if !(1..=16).contains(&self.k) {
            return Err(format!("[her] k must be in [1, 16], got {}", self.k));
        }
        for (name, x) in [
            ("threshold", self.effective_threshold()),
            ("goal_range", self.effective_goal_range()),
            ("proportional_bonus", self.proportional_bonus),
            ("distance_weight", self.distance_weight),
        ] {
            if !(x.is_finite() && x >= 0.0) {
                return Err(format!("[her] {name} must be finite and >= 0, got {x}"));
            }
        }
        if self.effective_threshold() == 0.0 {
            return Err("[her] threshold must be > 0".into());
        }
        Ok(())
    }

    /// The reward stored for a step with environment reward `env_reward` whose achieved goal is
    /// `distance` from the goal.
    pub fn reward(&self, env_reward: f64, distance: f64) -> f64 {
        let reached = distance < self.effective_threshold();
        let binary = if reached { 0.0 } else { -1.0 };
        match self.reward {
            GoalReward::Binary => binary,
            GoalReward::Sum => env_reward + binary,
            GoalReward::Proportional if reached => env_reward * (1.0 + self.proportional_bonus),
            GoalReward::Proportional => env_reward,
            GoalReward::Distance => env_reward - self.distance_weight * distance,
        }
    }

    /// The widths the networks and the replay see on `task`: its observation with the goal
    /// appended, and its action.
    pub fn dims(&self, task: Task) -> Dims {
        let own = task.dims();
        Dims { obs_dim: own.obs_dim + self.goal_dim(task), act_dim: own.act_dim }
    }

    /// The goal's length on `task` (0 with HER off or a goal the task has no slice for).
    pub fn goal_dim(&self, task: Task) -> usize {
        self.slice(task).map_or(0, |s| s.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn her(goal: GoalKind, reward: GoalReward) -> HerConfig {
        HerConfig { goal, reward, ..HerConfig::default() }
    }

    #[test]
    fn the_reward_forms_are_the_codes_and_the_texts() {
        // Speed goals: threshold 3.0. Reached at distance 1, not at distance 5.
        let cases = [
            (GoalReward::Binary, 0.0, -1.0),
            (GoalReward::Sum, 2.0, 1.0),
            (GoalReward::Proportional, 3.0, 2.0),
            (GoalReward::Distance, 2.0 - 0.05, 2.0 - 0.25),
        ];
        for (form, reached, missed) in cases {
            let c = her(GoalKind::Speed, form);
            assert_eq!(c.reward(2.0, 1.0), reached, "{form:?} reached");
            assert_eq!(c.reward(2.0, 5.0), missed, "{form:?} missed");
        }
        let position = her(GoalKind::Position, GoalReward::Binary);
        assert_eq!((position.effective_threshold(), position.reward(0.0, 9.0)), (10.0, 0.0));
    }

    #[test]
    fn goals_need_their_slice_of_the_observation() {
        let position = her(GoalKind::Position, GoalReward::Sum);
        assert!(position.validate(Task::AntV5, 1).unwrap_err().contains("ant-v5-xy"));
        assert_eq!(position.slice(Task::AntV5Xy), Ok(0..2));
        assert_eq!(her(GoalKind::Speed, GoalReward::Sum).slice(Task::AntV5), Ok(13..27));
        assert!(
            HerConfig { k: 0, ..her(GoalKind::Speed, GoalReward::Binary) }
                .validate(Task::AntRllab, 1)
                .is_err()
        );
        assert!(
            her(GoalKind::Speed, GoalReward::Binary)
                .validate(Task::AntRllab, 3)
                .unwrap_err()
                .contains("n_step")
        );
        let negative = HerConfig { threshold: Some(-1.0), ..her(GoalKind::Speed, GoalReward::Binary) };
        assert!(negative.validate(Task::AntRllab, 1).unwrap_err().contains("threshold"));
        // Off, nothing is checked and the widths are the task's.
        assert_eq!(HerConfig::default().validate(Task::AntV5, 5), Ok(()));
        assert_eq!(HerConfig::default().dims(Task::AntV5), Task::AntV5.dims());
    }
}
