//! Gymnasium Ant-v5, reproduced call for call (`gymnasium/envs/mujoco/ant_v5.py` with its defaults).

use crate::ant_model::{AntVariant, ant_mjcf};
use crate::episode::{Episode, MujocoTask};
use crate::physics::{NoiseStream, Physics};
use crate::{EnvError, EnvSpec, InitState, RewardTerms, Step, check_action, numpy};

const FRAME_SKIP: usize = 5;
const FORWARD_REWARD_WEIGHT: f64 = 1.0;
const CTRL_COST_WEIGHT: f64 = 0.5;
const CONTACT_COST_WEIGHT: f64 = 5e-4;
const HEALTHY_REWARD: f64 = 1.0;
const HEALTHY_Z: (f64, f64) = (0.2, 1.0);
const CONTACT_FORCE_RANGE: (f64, f64) = (-1.0, 1.0);
const RESET_NOISE_SCALE: f64 = 0.1;
const TORSO: usize = 1;
const MAX_EPISODE_STEPS: u32 = 1000;

/// The reward terms Ant-v5 reports in its step info, in this order.
pub const REWARD_TERMS: &[&str] =
    &["x_velocity", "reward_forward", "reward_ctrl", "reward_contact", "reward_survive"];

/// Gymnasium Ant-v5: 105-d observation (qpos[2:], qvel, clipped cfrc_ext of bodies 1..13), 8 torques;
/// or, as task `ant-v5-xy`, Ant-v5 with `exclude_current_positions_from_observation=False`: the
/// torso's x, y lead a 107-d observation (HER's position goals need them).
#[derive(Debug)]
pub struct AntV5 {
    episode: Episode,
    /// Observation starts at qpos[0] (`ant-v5-xy`) instead of qpos[2].
    first_qpos: usize,
}

impl AntV5 {
    /// A new Ant whose reset noise starts at `seed`. Call [`Environment::reset`] before stepping.
    pub fn new(seed: u64) -> Result<Self, EnvError> {
        Self::with_positions(seed, false)
    }

    /// Ant-v5 whose observation includes the torso's x, y (`include_positions`, task `ant-v5-xy`)
    /// or leaves them out (Gymnasium's default, task `ant-v5`).
    pub fn with_positions(seed: u64, include_positions: bool) -> Result<Self, EnvError> {
        let physics = Physics::load("ant-v5", &ant_mjcf(AntVariant::V5)?)?;
        let first_qpos = if include_positions { 0 } else { 2 };
        let spec = EnvSpec {
            name: if include_positions { "ant-v5-xy" } else { "ant-v5" },
            obs_dim: (physics.nq() - first_qpos) + physics.nv() + 13 * 6,
            act_dim: 8,
            action_low: vec![-1.0; 8],
            action_high: vec![1.0; 8],
            max_episode_steps: MAX_EPISODE_STEPS,
            dt: physics.timestep() * FRAME_SKIP as f64,
            nq: physics.nq(),
            nv: physics.nv(),
            reward_terms: REWARD_TERMS,
        };
        Ok(Self { episode: Episode::new(physics, spec, seed), first_qpos })
    }

    fn clipped_contact_forces(&self) -> impl Iterator<Item = f64> + '_ {
        let (lo, hi) = CONTACT_FORCE_RANGE;
        self.episode.physics.data().cfrc_ext().iter().flatten().map(move |f| f.clamp(lo, hi))
    }

    fn is_healthy(&self) -> bool {
        let z = self.episode.physics.data().qpos()[2];
        self.episode.physics.state_is_finite() && HEALTHY_Z.0 <= z && z <= HEALTHY_Z.1
    }

    fn torso_xy(&self) -> [f64; 2] {
        // xpos, not qpos: after mj_step it still holds the last internal forward evaluation, and that
        // is what Gymnasium differentiates.
        let p = self.episode.physics.data().xpos()[TORSO];
        [p[0], p[1]]
    }
}

impl MujocoTask for AntV5 {
    fn episode(&self) -> &Episode {
        &self.episode
    }

    fn episode_mut(&mut self) -> &mut Episode {
        &mut self.episode
    }

    fn start_state(noise: &mut NoiseStream, physics: &Physics) -> InitState {
        InitState {
            qpos: noise.uniform_around(&physics.qpos0(), RESET_NOISE_SCALE),
            qvel: noise.normal_around(&vec![0.0; physics.nv()], RESET_NOISE_SCALE),
        }
    }

    fn observation(&self) -> Vec<f64> {
        let data = self.episode.physics.data();
        let mut obs = Vec::with_capacity(self.episode.spec.obs_dim);
        obs.extend_from_slice(&data.qpos()[self.first_qpos..]);
        obs.extend_from_slice(data.qvel());
        // Row 0 is the world body, always zero: Ant-v5 leaves it out of the observation.
        obs.extend(self.clipped_contact_forces().skip(6));
        obs
    }

    fn advance(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        check_action(&self.episode.spec, action)?;
        let xy_before = self.torso_xy();
        self.episode.physics.step(action, FRAME_SKIP);
        self.episode.physics.rne_post_constraint();
        let xy_after = self.torso_xy();
        let x_velocity = (xy_after[0] - xy_before[0]) / self.episode.spec.dt;

        let healthy = self.is_healthy();
        let forward_reward = x_velocity * FORWARD_REWARD_WEIGHT;
        let healthy_reward = if healthy { HEALTHY_REWARD } else { 0.0 };
        // The control cost uses the action as given; MuJoCo clamps only what it simulates.
        let ctrl_cost = CTRL_COST_WEIGHT * numpy::sum_of_squares(action.iter().copied());
        let contact_cost = CONTACT_COST_WEIGHT * numpy::sum_of_squares(self.clipped_contact_forces());
        let reward = (forward_reward + healthy_reward) - (ctrl_cost + contact_cost);

        let truncated = self.episode.tick();
        Ok(Step {
            observation: self.observation(),
            reward,
            terminated: !healthy,
            truncated,
            terms: RewardTerms::new(&[x_velocity, forward_reward, -ctrl_cost, -contact_cost, healthy_reward]),
            goal: None,
        })
    }
}
