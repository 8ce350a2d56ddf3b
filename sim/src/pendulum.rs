//! Gymnasium InvertedPendulum-v5 (`gymnasium/envs/mujoco/inverted_pendulum_v5.py`): a cart-pole whose
//! pole must stay within 0.2 rad of upright; +1 per step while it does. Small and fast, for learning
//! checks (a good agent reaches the maximum return of 1000 within ~20K steps).

use crate::episode::{Episode, MujocoTask};
use crate::physics::{NoiseStream, Physics};
use crate::{EnvError, EnvSpec, InitState, RewardTerms, Step, check_action};

/// The pendulum MJCF.
pub const INVERTED_PENDULUM_MJCF: &str = include_str!("../assets/inverted_pendulum.xml");

const FRAME_SKIP: usize = 2;
const RESET_NOISE_SCALE: f64 = 0.01;
const MAX_ANGLE: f64 = 0.2;
const MAX_EPISODE_STEPS: u32 = 1000;

/// The reward terms this task reports.
pub const REWARD_TERMS: &[&str] = &["reward_survive"];

/// InvertedPendulum-v5: observation (cart x, pole angle, their velocities), one force in [-3, 3].
#[derive(Debug)]
pub struct InvertedPendulum {
    episode: Episode,
}

impl InvertedPendulum {
    /// A new pendulum whose reset noise starts at `seed`. Call [`Environment::reset`] before stepping.
    pub fn new(seed: u64) -> Result<Self, EnvError> {
        let physics = Physics::load("inverted-pendulum", INVERTED_PENDULUM_MJCF)?;
        let spec = EnvSpec {
            name: "inverted-pendulum",
            obs_dim: physics.nq() + physics.nv(),
            act_dim: 1,
            action_low: vec![-3.0],
            action_high: vec![3.0],
            max_episode_steps: MAX_EPISODE_STEPS,
            dt: physics.timestep() * FRAME_SKIP as f64,
            nq: physics.nq(),
            nv: physics.nv(),
            reward_terms: REWARD_TERMS,
        };
        Ok(Self { episode: Episode::new(physics, spec, seed) })
    }
}

impl MujocoTask for InvertedPendulum {
    fn episode(&self) -> &Episode {
        &self.episode
    }

    fn episode_mut(&mut self) -> &mut Episode {
        &mut self.episode
    }

    fn start_state(noise: &mut NoiseStream, physics: &Physics) -> InitState {
        InitState {
            qpos: noise.uniform_around(&physics.qpos0(), RESET_NOISE_SCALE),
            qvel: noise.uniform_around(&vec![0.0; physics.nv()], RESET_NOISE_SCALE),
        }
    }

    fn observation(&self) -> Vec<f64> {
        let data = self.episode.physics.data();
        data.qpos().iter().chain(data.qvel()).copied().collect()
    }

    fn advance(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        check_action(&self.episode.spec, action)?;
        self.episode.physics.step(action, FRAME_SKIP);
        let observation = self.observation();
        let terminated = !observation.iter().all(|v| v.is_finite()) || observation[1].abs() > MAX_ANGLE;
        let reward = if terminated { 0.0 } else { 1.0 };
        let truncated = self.episode.tick();
        Ok(Step {
            observation,
            reward,
            terminated,
            truncated,
            terms: RewardTerms::new(&[reward]),
            goal: None,
        })
    }
}
