use crate::EnvError;

/// What a learner or executor needs to know about a task without simulating it.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvSpec {
    /// Task name, as accepted by [`crate::Task`].
    pub name: &'static str,
    /// Observation length.
    pub obs_dim: usize,
    /// Action length.
    pub act_dim: usize,
    /// Lower action bound per component (actions outside are treated as the reference does).
    pub action_low: Vec<f64>,
    /// Upper action bound per component.
    pub action_high: Vec<f64>,
    /// Episodes are truncated after this many steps.
    pub max_episode_steps: u32,
    /// Simulated seconds per step.
    pub dt: f64,
    /// Number of generalised coordinates (length of qpos).
    pub nq: usize,
    /// Number of degrees of freedom (length of qvel).
    pub nv: usize,
    /// Names of the per-step reward terms, in the order of [`RewardTerms::values`].
    pub reward_terms: &'static [&'static str],
}

impl EnvSpec {
    /// Maps a squashed policy output in [-1, 1] onto the action box: `centre + u * half_width` per
    /// component (the identity, exactly, for tasks whose box is [-1, 1]).
    pub fn action_from_unit(&self, unit: &[f32]) -> Vec<f64> {
        unit.iter()
            .zip(self.action_low.iter().zip(&self.action_high))
            .map(|(u, (lo, hi))| (lo + hi) / 2.0 + f64::from(*u) * (hi - lo) / 2.0)
            .collect()
    }
}

/// Named per-step reward terms (their names are in [`EnvSpec::reward_terms`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct RewardTerms {
    values: [f64; RewardTerms::MAX],
    len: usize,
}

impl RewardTerms {
    /// Most terms any task reports.
    pub const MAX: usize = 8;

    /// Terms from a list of values (at most [`Self::MAX`]).
    pub(crate) fn new(values: &[f64]) -> Self {
        let mut terms = Self { values: [0.0; Self::MAX], len: values.len().min(Self::MAX) };
        terms.values[..terms.len].copy_from_slice(&values[..terms.len]);
        terms
    }

    /// The values, in the order of the task's [`EnvSpec::reward_terms`].
    pub fn values(&self) -> &[f64] {
        &self.values[..self.len]
    }
}

/// The outcome of one [`crate::Environment::step`].
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    /// Observation after the step.
    pub observation: Vec<f64>,
    /// Reward for the step (unscaled).
    pub reward: f64,
    /// The episode ended inside the task (e.g. the Ant fell): no bootstrapping past it.
    pub terminated: bool,
    /// The episode hit its time limit: the state is not terminal, bootstrapping continues.
    pub truncated: bool,
    /// The reward's parts, as the reference reports them.
    pub terms: RewardTerms,
    /// With a goal ([`crate::her::GoalEnv`]): where the step got relative to the episode's goal.
    pub goal: Option<crate::her::GoalStatus>,
}

/// An exact physical state to start an episode from: the full `qpos` followed by the full `qvel`.
#[derive(Debug, Clone, PartialEq)]
pub struct InitState {
    /// Generalised positions (nq values).
    pub qpos: Vec<f64>,
    /// Generalised velocities (nv values).
    pub qvel: Vec<f64>,
}

impl InitState {
    /// Splits one row `qpos ++ qvel` for a model with `nq` positions and `nv` velocities.
    pub fn from_row(row: &[f64], nq: usize, nv: usize) -> Result<Self, EnvError> {
        if row.len() != nq + nv {
            return Err(EnvError::StateDim { expected: nq + nv, found: row.len() });
        }
        if let Some(index) = row.iter().position(|v| !v.is_finite()) {
            return Err(EnvError::NonFiniteState { index });
        }
        Ok(Self { qpos: row[..nq].to_vec(), qvel: row[nq..].to_vec() })
    }
}
