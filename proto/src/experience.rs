//! Experience: what executors send the replay server, and the transition columns that sampled
//! batches carry back to the learner.

use serde::{Deserialize, Serialize};

use crate::check;
use crate::codec::{Message, MessageKind, sealed::Sealed};
use crate::error::ValidationError;

/// `n` transitions stored column-wise: each column is one contiguous row-major array, so the replay
/// server copies rows with `copy_from_slice` and the learner builds a tensor from a column directly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transitions {
    /// Observation width.
    pub obs_dim: u32,
    /// Action width.
    pub act_dim: u32,
    /// `n * obs_dim` floats, row-major.
    #[serde(with = "crate::blob::f32s")]
    pub observations: Vec<f32>,
    /// `n * act_dim` floats in the environment's action space, row-major.
    #[serde(with = "crate::blob::f32s")]
    pub actions: Vec<f32>,
    /// `n` rewards.
    #[serde(with = "crate::blob::f32s")]
    pub rewards: Vec<f32>,
    /// `n * obs_dim` floats, row-major: the observation after the action.
    #[serde(with = "crate::blob::f32s")]
    pub next_observations: Vec<f32>,
    /// `n` flags: the environment terminated (the bootstrap is cut). A time-limit truncation is
    /// `false` here, because the next state's value still counts.
    pub terminated: Vec<bool>,
}

/// One transition, borrowed: the row type for [`Transitions::push`] and [`Transitions::get`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transition<'a> {
    /// Observation before the action (`obs_dim` floats).
    pub observation: &'a [f32],
    /// Action taken (`act_dim` floats).
    pub action: &'a [f32],
    /// Reward received.
    pub reward: f32,
    /// Observation after the action (`obs_dim` floats).
    pub next_observation: &'a [f32],
    /// Environment termination (not time-limit truncation).
    pub terminated: bool,
}

impl Transitions {
    /// Empty columns for `obs_dim`/`act_dim`, with room for `capacity` transitions.
    pub fn with_capacity(obs_dim: u32, act_dim: u32, capacity: usize) -> Transitions {
        let (o, a) = (obs_dim as usize, act_dim as usize);
        Transitions {
            obs_dim,
            act_dim,
            observations: Vec::with_capacity(capacity * o),
            actions: Vec::with_capacity(capacity * a),
            rewards: Vec::with_capacity(capacity),
            next_observations: Vec::with_capacity(capacity * o),
            terminated: Vec::with_capacity(capacity),
        }
    }

    /// Number of transitions (the length of `rewards`).
    pub fn len(&self) -> usize {
        self.rewards.len()
    }

    /// No transitions.
    pub fn is_empty(&self) -> bool {
        self.rewards.is_empty()
    }

    /// Appends one transition; rejects rows whose widths differ from `obs_dim`/`act_dim`, leaving
    /// the columns untouched.
    pub fn push(&mut self, t: Transition<'_>) -> Result<(), ValidationError> {
        let (o, a) = (self.obs_dim as usize, self.act_dim as usize);
        check::len("observation", o, t.observation.len())?;
        check::len("action", a, t.action.len())?;
        check::len("next_observation", o, t.next_observation.len())?;
        self.observations.extend_from_slice(t.observation);
        self.actions.extend_from_slice(t.action);
        self.rewards.push(t.reward);
        self.next_observations.extend_from_slice(t.next_observation);
        self.terminated.push(t.terminated);
        Ok(())
    }

    /// Moves the first `n` transitions (all, if fewer) into a batch of their own; the rest stay.
    pub fn split_front(&mut self, n: usize) -> Transitions {
        let n = n.min(self.len());
        let (o, a) = (self.obs_dim as usize, self.act_dim as usize);
        Transitions {
            obs_dim: self.obs_dim,
            act_dim: self.act_dim,
            observations: self.observations.drain(..n * o).collect(),
            actions: self.actions.drain(..n * a).collect(),
            rewards: self.rewards.drain(..n).collect(),
            next_observations: self.next_observations.drain(..n * o).collect(),
            terminated: self.terminated.drain(..n).collect(),
        }
    }

    /// Transition `i`, if the columns hold it.
    pub fn get(&self, i: usize) -> Option<Transition<'_>> {
        // Checked, so an absurd index is `None` rather than an overflow.
        let rows =
            |width: u32| Some(i.checked_mul(width as usize)?..i.checked_add(1)?.checked_mul(width as usize)?);
        Some(Transition {
            observation: self.observations.get(rows(self.obs_dim)?)?,
            action: self.actions.get(rows(self.act_dim)?)?,
            reward: *self.rewards.get(i)?,
            next_observation: self.next_observations.get(rows(self.obs_dim)?)?,
            terminated: *self.terminated.get(i)?,
        })
    }

    /// Encoded size estimate: every float column, a byte per flag, and room for length prefixes.
    pub(crate) fn payload_size_hint(&self) -> usize {
        let floats =
            self.observations.len() + self.actions.len() + self.rewards.len() + self.next_observations.len();
        4 * floats + self.terminated.len() + 64
    }

    /// Dimensions in 1..=[`crate::MAX_DIM`], 1..=[`crate::MAX_BATCH_LEN`] transitions, every
    /// column `n` rows long, every float finite.
    pub fn validate(&self) -> Result<(), ValidationError> {
        check::dim("obs_dim", self.obs_dim)?;
        check::dim("act_dim", self.act_dim)?;
        let n = self.len();
        check::batch_len("rewards", n)?;
        let (o, a) = (self.obs_dim as usize, self.act_dim as usize);
        check::len("observations", n * o, self.observations.len())?;
        check::len("actions", n * a, self.actions.len())?;
        check::len("next_observations", n * o, self.next_observations.len())?;
        check::len("terminated", n, self.terminated.len())?;
        check::finite("observations", &self.observations)?;
        check::finite("actions", &self.actions)?;
        check::finite("rewards", &self.rewards)?;
        check::finite("next_observations", &self.next_observations)
    }
}

/// A batch of transitions from one executor; topic `experience/<executor_id>`, executor → replay server.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExperienceBatch {
    /// The sending executor.
    pub executor_id: u32,
    /// The sending process's stream: a nonzero id drawn at its start, so that (`executor_id`,
    /// `stream`, `seq`) names one batch across restarts and re-sends, and the replay server stores
    /// each at most once (see [`crate::DurableMarks`]). 0: a sender without a spool; not deduplicated.
    pub stream: u64,
    /// Batch sequence number within the stream, starting at 0; a gap means batches were lost.
    pub seq: u64,
    /// Version of the weights that chose these actions (policy lag = learner's step − this).
    pub weights_version: u64,
    /// The executor's cumulative environment steps after the last transition of this batch.
    pub env_steps: u64,
    /// The transitions; none in a marker (see [`Message::validate`] for this type).
    pub transitions: Transitions,
    /// `n` absolute TD errors `|δ|` the executor computed, for the initial priority; the replay
    /// server applies `p = (|δ| + ε)^α` itself, so α and ε live in one place.
    #[serde(with = "crate::blob::f32s")]
    pub td_errors: Vec<f32>,
}

impl ExperienceBatch {
    /// Number of transitions.
    pub fn len(&self) -> usize {
        self.transitions.len()
    }

    /// No transitions.
    pub fn is_empty(&self) -> bool {
        self.transitions.is_empty()
    }
}

impl Sealed for ExperienceBatch {
    fn payload_size_hint(&self) -> usize {
        self.transitions.payload_size_hint() + 4 * self.td_errors.len() + 64
    }
}

impl Message for ExperienceBatch {
    const KIND: MessageKind = MessageKind::ExperienceBatch;

    fn validate(&self) -> Result<(), ValidationError> {
        if self.is_empty() {
            // A marker: in deterministic mode an executor says "my steps up to `env_steps` are all
            // sent" at each block's end, whether or not the block's last steps made transitions.
            check::dim("obs_dim", self.transitions.obs_dim)?;
            check::dim("act_dim", self.transitions.act_dim)?;
            let t = &self.transitions;
            check::len("observations", 0, t.observations.len())?;
            check::len("actions", 0, t.actions.len())?;
            check::len("next_observations", 0, t.next_observations.len())?;
            check::len("terminated", 0, t.terminated.len())?;
            return check::len("td_errors", 0, self.td_errors.len());
        }
        self.transitions.validate()?;
        check::len("td_errors", self.len(), self.td_errors.len())?;
        check::finite_non_negative("td_errors", &self.td_errors)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Owned data for one row, so tests can borrow it as a [`Transition`].
    struct Row {
        observation: Vec<f32>,
        action: Vec<f32>,
        next_observation: Vec<f32>,
        reward: f32,
    }

    impl Row {
        fn new(x: f32) -> Row {
            Row {
                observation: vec![x, x + 1.0, x + 2.0],
                action: vec![-x, x],
                next_observation: vec![x + 3.0, x + 4.0, x + 5.0],
                reward: x,
            }
        }

        fn view(&self) -> Transition<'_> {
            Transition {
                observation: &self.observation,
                action: &self.action,
                reward: self.reward,
                next_observation: &self.next_observation,
                terminated: self.reward > 1.0,
            }
        }
    }

    #[test]
    fn push_and_get_agree() {
        let (a, b) = (Row::new(1.0), Row::new(2.0));
        let mut t = Transitions::with_capacity(3, 2, 2);
        t.push(a.view()).unwrap();
        t.push(b.view()).unwrap();
        assert_eq!(t.len(), 2);
        assert_eq!(t.get(0), Some(a.view()));
        assert_eq!(t.get(1), Some(b.view()));
        assert_eq!(t.get(2), None);
        assert_eq!(t.get(usize::MAX), None);
        assert_eq!(t.validate(), Ok(()));
    }

    #[test]
    fn split_front_moves_the_first_rows_and_keeps_the_rest() {
        let rows: Vec<Row> = (0..3).map(|i| Row::new(i as f32)).collect();
        let mut t = Transitions::with_capacity(3, 2, 3);
        rows.iter().for_each(|r| t.push(r.view()).unwrap());
        let front = t.split_front(2);
        assert_eq!((front.len(), t.len()), (2, 1));
        assert_eq!((front.get(1), t.get(0)), (Some(rows[1].view()), Some(rows[2].view())));
        assert_eq!((front.validate(), t.validate()), (Ok(()), Ok(())));
        assert_eq!(t.split_front(5).len(), 1);
        assert!(t.is_empty());
    }

    #[test]
    fn push_rejects_wrong_widths_without_partial_writes() {
        let mut t = Transitions::with_capacity(3, 2, 1);
        let row = Row::new(1.0);
        let bad = Transition { action: &[1.0], ..row.view() };
        assert_eq!(
            t.push(bad),
            Err(ValidationError::LengthMismatch { field: "action", expected: 2, found: 1 })
        );
        assert!(t.is_empty() && t.observations.is_empty());
    }

    #[test]
    fn validate_catches_each_inconsistency() {
        let mut good = Transitions::with_capacity(3, 2, 1);
        good.push(Row::new(1.0).view()).unwrap();
        let empty = Transitions::with_capacity(3, 2, 0);
        assert_eq!(empty.validate(), Err(ValidationError::Empty { field: "rewards" }));
        let zero_dim = Transitions { obs_dim: 0, ..good.clone() };
        assert!(matches!(zero_dim.validate(), Err(ValidationError::BadDimension { field: "obs_dim", .. })));
        let mut short = good.clone();
        short.next_observations.pop();
        assert!(matches!(
            short.validate(),
            Err(ValidationError::LengthMismatch { field: "next_observations", .. })
        ));
        let mut nan = good.clone();
        nan.actions[1] = f32::NAN;
        assert_eq!(nan.validate(), Err(ValidationError::NonFinite { field: "actions", index: 1 }));
        let batch = ExperienceBatch {
            executor_id: 0,
            stream: 0,
            seq: 0,
            weights_version: 0,
            env_steps: 1,
            transitions: good,
            td_errors: vec![-0.5],
        };
        assert_eq!(batch.validate(), Err(ValidationError::Negative { field: "td_errors", index: 0 }));
        // A marker (no transitions) is valid, but only with every column empty.
        let marker = ExperienceBatch { transitions: empty.clone(), td_errors: vec![], ..batch.clone() };
        assert_eq!(marker.validate(), Ok(()));
        let mut ragged = marker.clone();
        ragged.transitions.actions.push(1.0);
        assert!(matches!(ragged.validate(), Err(ValidationError::LengthMismatch { field: "actions", .. })));
        let no_dims = ExperienceBatch { transitions: Transitions { obs_dim: 0, ..empty }, ..marker };
        assert!(no_dims.validate().is_err());
        // encode reserves the whole frame up front (the hint is an upper bound here), so it never reallocates.
        let frame = crate::encode(&batch);
        assert!(frame.len() <= frame.capacity());
        assert_eq!(frame.capacity(), crate::codec::HEADER_LEN + batch.payload_size_hint());
    }
}
