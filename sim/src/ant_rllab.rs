//! The dissertation's Ant: rllab's `AntEnv` under `normalize()` (`rllab/envs/mujoco/ant_env.py`), on
//! MuJoCo 3.17 instead of 1.31 (so returns are close to, not identical with, the paper's).

use mujoco_rs::prelude::MjtObjBase;

use crate::ant_model::{AntVariant, ant_mjcf};
use crate::episode::{Episode, MujocoTask};
use crate::physics::{NoiseStream, Physics};
use crate::{EnvError, EnvSpec, InitState, RewardTerms, Step, check_action, numpy};

/// rllab's `normalize()` maps [-1, 1] onto the motors' ±150 range.
const ACTION_SCALE: f64 = 150.0;
const CTRL_COST_WEIGHT: f64 = 0.5 * 1e-2;
const CONTACT_COST_WEIGHT: f64 = 0.5 * 1e-3;
const SURVIVE_REWARD: f64 = 0.05;
const HEALTHY_Z: (f64, f64) = (0.2, 1.0);
const QPOS_NOISE: f64 = 0.01;
const QVEL_NOISE: f64 = 0.1;
const TORSO: usize = 1;
const MAX_EPISODE_STEPS: u32 = 1000;
/// rllab's `init_qpos` (the model's custom numeric): torso at 0.55 m, ankles bent by ±1 rad.
const INIT_QPOS: [f64; 15] = [0.0, 0.0, 0.55, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0];

/// The reward terms this task reports, in this order.
pub const REWARD_TERMS: &[&str] =
    &["x_velocity", "reward_forward", "reward_ctrl", "reward_contact", "reward_survive"];

/// rllab Ant: 125-d observation (qpos, qvel, clipped cfrc_ext of all 14 bodies, torso xmat, torso
/// subtree centre of mass), actions in [-1, 1] scaled to ±150 and clipped.
#[derive(Debug)]
pub struct AntRllab {
    episode: Episode,
}

impl AntRllab {
    /// A new Ant whose reset noise starts at `seed`. Call [`Environment::reset`] before stepping.
    pub fn new(seed: u64) -> Result<Self, EnvError> {
        let physics = Physics::load("ant-rllab", &ant_mjcf(AntVariant::Rllab)?)?;
        let spec = EnvSpec {
            name: "ant-rllab",
            obs_dim: physics.nq() + physics.nv() + 14 * 6 + 9 + 3,
            act_dim: 8,
            action_low: vec![-1.0; 8],
            action_high: vec![1.0; 8],
            max_episode_steps: MAX_EPISODE_STEPS,
            dt: physics.timestep(),
            nq: physics.nq(),
            nv: physics.nv(),
            reward_terms: REWARD_TERMS,
        };
        Ok(Self { episode: Episode::new(physics, spec, seed) })
    }

    fn clipped_contact_forces(&self) -> impl Iterator<Item = f64> + '_ {
        self.episode.physics.data().cfrc_ext().iter().flatten().map(|f| f.clamp(-1.0, 1.0))
    }

    /// rllab's `get_body_comvel("torso")`: the mass-weighted mean linear velocity of the torso's
    /// subtree (every body but the world), each from `mj_objectVelocity` in world coordinates.
    fn torso_subtree_x_velocity(&self) -> f64 {
        let data = self.episode.physics.data();
        let masses = self.episode.physics.model().body_mass();
        let (mut momentum, mut mass) = (0.0, 0.0);
        for (body, m) in masses.iter().enumerate().skip(TORSO) {
            let velocity = data.object_velocity(MjtObjBase::mjOBJ_BODY, body, false);
            momentum += m * velocity[3];
            mass += m;
        }
        momentum / mass
    }
}

impl MujocoTask for AntRllab {
    fn episode(&self) -> &Episode {
        &self.episode
    }

    fn episode_mut(&mut self) -> &mut Episode {
        &mut self.episode
    }

    fn start_state(noise: &mut NoiseStream, physics: &Physics) -> InitState {
        InitState {
            qpos: noise.normal_around(&INIT_QPOS, QPOS_NOISE),
            qvel: noise.normal_around(&vec![0.0; physics.nv()], QVEL_NOISE),
        }
    }

    fn observation(&self) -> Vec<f64> {
        let data = self.episode.physics.data();
        let mut obs = Vec::with_capacity(self.episode.spec.obs_dim);
        obs.extend_from_slice(data.qpos());
        obs.extend_from_slice(data.qvel());
        obs.extend(self.clipped_contact_forces());
        obs.extend_from_slice(&data.xmat()[TORSO]);
        obs.extend_from_slice(&data.subtree_com()[TORSO]);
        obs
    }

    fn advance(&mut self, action: &[f64]) -> Result<Step, EnvError> {
        check_action(&self.episode.spec, action)?;
        // normalize(): lb + (a + 1)(ub - lb)/2, clipped to [lb, ub]; the costs see the clipped action.
        let unit: Vec<f64> = action.iter().map(|a| a.clamp(-1.0, 1.0)).collect();
        let ctrl: Vec<f64> = unit.iter().map(|a| a * ACTION_SCALE).collect();
        self.episode.physics.step(&ctrl, 1);
        // rllab calls forward() after stepping; MuJoCo >= 2 also needs rnePostConstraint for cfrc_ext.
        self.episode.physics.forward();
        self.episode.physics.rne_post_constraint();

        let x_velocity = self.torso_subtree_x_velocity();
        let ctrl_cost = CTRL_COST_WEIGHT * numpy::sum_of_squares(unit.iter().copied());
        let contact_cost = CONTACT_COST_WEIGHT * numpy::sum_of_squares(self.clipped_contact_forces());
        let reward = x_velocity - ctrl_cost - contact_cost + SURVIVE_REWARD;
        let z = self.episode.physics.data().qpos()[2];
        let alive = self.episode.physics.state_is_finite() && (HEALTHY_Z.0..=HEALTHY_Z.1).contains(&z);

        let truncated = self.episode.tick();
        Ok(Step {
            observation: self.observation(),
            reward,
            terminated: !alive,
            truncated,
            terms: RewardTerms::new(&[x_velocity, x_velocity, -ctrl_cost, -contact_cost, SURVIVE_REWARD]),
            goal: None,
        })
    }
}
