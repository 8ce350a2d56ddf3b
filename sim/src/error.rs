use thiserror::Error;

/// Why an environment refused a call.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum EnvError {
    /// A task's settings do not fit it (for example a goal the observation has no slice for).
    #[error("{0}")]
    Config(String),
    /// The action has the wrong number of components.
    #[error("action has {found} components, the task expects {expected}")]
    ActionDim {
        /// The task's action dimension.
        expected: usize,
        /// The length that was given.
        found: usize,
    },
    /// An action component is NaN or infinite.
    #[error("action component {index} is not finite ({value})")]
    NonFiniteAction {
        /// Position of the first bad component.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// An initial state has the wrong number of qpos/qvel values.
    #[error("initial state has {found} values, the model needs nq + nv = {expected}")]
    StateDim {
        /// nq + nv of the model.
        expected: usize,
        /// The length that was given.
        found: usize,
    },
    /// An initial state value is NaN or infinite.
    #[error("initial state value {index} is not finite")]
    NonFiniteState {
        /// Position of the first bad value.
        index: usize,
    },
    /// The task name is not one of the known tasks.
    #[error(transparent)]
    UnknownTask(#[from] run::UnknownTask),
    /// A picture that cannot be drawn.
    #[error("cannot render: {0}")]
    Render(String),
    /// MuJoCo refused the model (a bug in the bundled MJCF, never user input).
    #[error("MuJoCo could not load the {task} model: {message}")]
    Model {
        /// Which model.
        task: &'static str,
        /// MuJoCo's message.
        message: String,
    },
}
