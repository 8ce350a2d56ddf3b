//! The MuJoCo model/data pair every task steps, and the process-wide MuJoCo set-up.

use std::sync::{Arc, Once};

use mujoco_rs::prelude::*;
use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::{EnvError, InitState};

/// A loaded model with its simulation state, owned by one environment (one thread).
pub struct Physics {
    model: Arc<MjModel>,
    data: MjData<Arc<MjModel>>,
}

impl std::fmt::Debug for Physics {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = self.data.model().ffi();
        f.debug_struct("Physics").field("nq", &m.nq).field("nv", &m.nv).field("nu", &m.nu).finish()
    }
}

/// Routes MuJoCo's messages to stderr only. By default MuJoCo also appends them to `MUJOCO_LOG.TXT`
/// in the working directory, which would litter every run folder and the repository during tests.
fn configure_mujoco_logging() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let config = log_config().with_logto_file(false);
        // SAFETY: this runs once, before this process loads any model (every model is loaded through
        // `Physics::load`, which waits for this `Once`), so no other MuJoCo call can run concurrently.
        unsafe { set_log_config(config) };
    });
}

impl Physics {
    /// Compiles an MJCF document. `task` only names the model in errors.
    pub fn load(task: &'static str, mjcf: &str) -> Result<Self, EnvError> {
        configure_mujoco_logging();
        let model =
            MjModel::from_xml_string(mjcf).map_err(|e| EnvError::Model { task, message: e.to_string() })?;
        let model = Arc::new(model);
        Ok(Self { data: MjData::new(Arc::clone(&model)), model })
    }

    /// The compiled model, shared (a renderer keeps its own data of it).
    pub fn shared_model(&self) -> Arc<MjModel> {
        Arc::clone(&self.model)
    }

    /// The compiled model.
    pub fn model(&self) -> &MjModel {
        self.data.model()
    }

    /// The simulation state.
    pub fn data(&self) -> &MjData<Arc<MjModel>> {
        &self.data
    }

    /// Number of generalised coordinates.
    pub fn nq(&self) -> usize {
        self.model().ffi().nq as usize
    }

    /// Number of degrees of freedom.
    pub fn nv(&self) -> usize {
        self.model().ffi().nv as usize
    }

    /// The physics timestep in seconds.
    pub fn timestep(&self) -> f64 {
        self.model().opt().timestep
    }

    /// The model's reference configuration `qpos0` (Gymnasium's `init_qpos`).
    pub fn qpos0(&self) -> Vec<f64> {
        self.model().qpos0().to_vec()
    }

    /// Gymnasium's `mj_resetData` followed by `set_state(qpos, qvel)`: everything else (time, controls,
    /// warm starts) goes back to its default, then `mj_forward` makes positions and contacts consistent.
    pub fn reset_to(&mut self, state: &InitState) -> Result<(), EnvError> {
        let expected = self.nq() + self.nv();
        if state.qpos.len() != self.nq() || state.qvel.len() != self.nv() {
            return Err(EnvError::StateDim { expected, found: state.qpos.len() + state.qvel.len() });
        }
        self.data.reset();
        self.data.qpos_mut().copy_from_slice(&state.qpos);
        self.data.qvel_mut().copy_from_slice(&state.qvel);
        self.data.forward();
        Ok(())
    }

    /// Sets the controls (MuJoCo clamps them to each actuator's ctrlrange) and runs `n` physics steps.
    pub fn step(&mut self, ctrl: &[f64], n: usize) {
        self.data.ctrl_mut().copy_from_slice(ctrl);
        for _ in 0..n {
            self.data.step();
        }
    }

    /// Fills `cfrc_ext` (external contact forces per body). Since MuJoCo 2.0 `mj_step` no longer does,
    /// and the Ant's observation and contact cost need it.
    pub fn rne_post_constraint(&mut self) {
        self.data.rne_post_constraint();
    }

    /// Recomputes positions, velocities and forces for the current state (`mj_forward`).
    pub fn forward(&mut self) {
        self.data.forward();
    }

    /// True when every qpos and qvel value is finite.
    pub fn state_is_finite(&self) -> bool {
        self.data.qpos().iter().chain(self.data.qvel()).all(|v| v.is_finite())
    }
}

/// The reset-noise stream of one environment: seeded, so resets are reproducible.
#[derive(Debug)]
pub struct NoiseStream {
    rng: StdRng,
}

impl NoiseStream {
    /// A stream starting at `seed`.
    pub fn new(seed: u64) -> Self {
        Self { rng: StdRng::seed_from_u64(seed) }
    }

    /// Restarts from `seed` when given (a seeded reset), else keeps going.
    pub fn reseed(&mut self, seed: Option<u64>) {
        if let Some(seed) = seed {
            self.rng = StdRng::seed_from_u64(seed);
        }
    }

    /// `base + U[-scale, scale)` element-wise.
    pub fn uniform_around(&mut self, base: &[f64], scale: f64) -> Vec<f64> {
        use rand::Rng;
        base.iter().map(|b| b + self.rng.random_range(-scale..scale)).collect()
    }

    /// `base + N(0, scale²)` element-wise.
    pub fn normal_around(&mut self, base: &[f64], scale: f64) -> Vec<f64> {
        use rand::Rng;
        base.iter().map(|b| b + scale * self.rng.sample::<f64, _>(rand_distr::StandardNormal)).collect()
    }
}
