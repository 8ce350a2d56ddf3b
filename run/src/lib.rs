//! A run file, read once ([`RunSpec`]): the tasks and their widths ([`Task`]), the shared tables
//! (`[train]`'s task and seed, `[her]`, `[hierarchy]`), deterministic mode's schedule
//! ([`Lockstep`]), the `SACLSP_*` overrides ([`Overrides`]) and each crate's own table through
//! [`RoleConfig`]. No simulator, no bus, no tensors: the replay and param servers size their
//! buffers and check weights from it without linking MuJoCo.
//!
//! | file | what |
//! |---|---|
//! | `spec.rs` | [`RunSpec`], [`RoleConfig`], `[train]`'s shared keys, `[hierarchy]` |
//! | `task.rs` | [`Task`]: names and widths |
//! | `her.rs` | [`HerConfig`]: the `[her]` table |
//! | `lockstep.rs` | [`Lockstep`]: deterministic mode's schedule |
//! | `overrides.rs` | [`Overrides`]: the `SACLSP_*` variables |
//! | `table.rs` | typed tables of a parsed file |
//! | `seed.rs` | splitmix64, the one seed mixer |
#![deny(missing_docs)]

pub mod her;
pub mod lockstep;
pub mod overrides;
pub mod seed;
mod spec;
pub mod table;
mod task;

pub use her::{GoalKind, GoalReward, HerConfig};
pub use lockstep::{Lockstep, LockstepKeys};
pub use overrides::Overrides;
pub use seed::{mix_seed, splitmix64};
pub use spec::{HierarchyKeys, RoleConfig, RunError, RunSpec, TrainKeys};
pub use task::{Dims, Task, UnknownTask};
