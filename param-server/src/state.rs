//! The param server's state, sans-IO: encoded messages in, announcements and stats out.

use std::time::Instant;

use node::Rejects;
use proto::{
    BarrierReport, BlockedReason, ContentHash, GlobalStep, LearnerStep, NodeId, StatsReport, WeightsSnapshot,
};

use crate::starvation::StarvationWatch;
use crate::step_guard::{Implausible, StepGuard};
use crate::{BadBody, Barrier, BarrierRule, ParamStore, Rejected, Schema, check_body};

/// What the param server has done.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub struct StateCounts {
    /// Weight snapshots taken (newer than the one held).
    pub snapshots_accepted: u64,
    /// Snapshots of the version already held, sent again (the learner's re-send to a param server
    /// that starts listening): ignored, not rejected.
    pub snapshots_repeated: u64,
    /// Weight queries answered (with weights or an error).
    pub weights_served: u64,
    /// Bytes of weights sent in those answers.
    pub weights_served_bytes: u64,
    /// Weight versions pushed on `params/stream` (each once, whatever the number of executors).
    pub weights_pushed: u64,
    /// Bytes of weights pushed.
    pub weights_pushed_bytes: u64,
    /// Learner progress messages received.
    pub learner_steps: u64,
    /// Barrier reports received.
    pub barrier_reports: u64,
    /// Reports from executors not (or no longer) alive, ignored: sent just before dying, or before
    /// the sender's liveliness token arrived.
    pub reports_from_unknown: u64,
    /// Executors seen joining, and leaving (liveliness).
    pub executors_joined: u64,
    /// Executors seen leaving or dying.
    pub executors_left: u64,
    /// Warm-up refills granted to a starved learner.
    pub refills: u64,
}

/// Barrier, weights store, counters and rejections.
#[derive(Debug)]
pub struct State {
    barrier: Barrier,
    store: ParamStore,
    counts: StateCounts,
    rejects: Rejects,
    /// When the learner's step last moved, to say how long it has been still.
    learner_moved_at: Instant,
    /// Starved learner and blocked barrier: when they make a deadlock.
    starvation: StarvationWatch,
    /// The tensor names and shapes every body must have: the run's networks', or else those of
    /// the first weights taken.
    schema: Option<Schema>,
    /// Refuses learner steps that move implausibly far (a forged frame would pin the barrier).
    step_guard: StepGuard,
    /// The content hash of the frozen levels served (hierarchies); every weights frame must carry it.
    stack: Option<ContentHash>,
}

impl State {
    /// Empty state under `rule`.
    pub fn new(rule: BarrierRule) -> Self {
        Self {
            barrier: Barrier::new(rule),
            store: ParamStore::default(),
            counts: StateCounts::default(),
            rejects: Rejects::default(),
            learner_moved_at: Instant::now(),
            starvation: StarvationWatch::default(),
            schema: None,
            step_guard: StepGuard::default(),
            stack: None,
        }
    }

    /// The same state taking only weights trained on the frozen levels hashed `stack`.
    pub fn with_stack(self, stack: ContentHash) -> Self {
        Self { stack: Some(stack), ..self }
    }

    /// The same state checking every weights body against `schema` (the run's networks) from the
    /// first frame on, instead of against the first frame taken.
    pub fn with_schema(self, schema: Schema) -> Self {
        Self { schema: Some(schema), ..self }
    }

    /// The same state with learner steps bounded by `guard` instead of the default.
    pub fn with_step_guard(self, guard: StepGuard) -> Self {
        Self { step_guard: guard, ..self }
    }

    /// Takes the learner's `step` (from `what`) into the barrier unless it moves implausibly far;
    /// returns whether the global step moved.
    fn learner_reached(&mut self, step: u64, what: &str) -> bool {
        let now = Instant::now();
        if let Err(Implausible { step, held, allowance }) = self.step_guard.check(step, now) {
            let detail = format!("step {step} from {what} is more than {allowance} past {held}");
            self.rejects.record(&format!("{what}/implausible_step"), &detail, now);
            return false;
        }
        let moved = self.barrier.learner_step(step);
        if moved {
            self.learner_moved_at = now;
        }
        moved
    }

    /// The version of the newest weights taken, if any.
    pub fn latest_version(&self) -> Option<u64> {
        self.store.latest().map(|s| s.version)
    }

    /// A frame from `params/publish`. Returns whether it became the latest weights.
    pub fn on_weights(&mut self, bytes: &[u8]) -> bool {
        let snapshot = match proto::decode::<WeightsSnapshot>(bytes) {
            Ok(snapshot) => snapshot,
            Err(error) => {
                self.rejects.decode_failed("weights", &error);
                return false;
            }
        };
        if let Some(detail) = snapshot.stack_mismatch(self.stack) {
            self.rejects.record("weights/stack_mismatch", &detail, Instant::now());
            return false;
        }
        // Repeats and old versions are refused by the store before their bodies are read.
        if self.store.takes(snapshot.version) {
            match check_body(&snapshot.safetensors, self.schema.as_ref()) {
                Ok(schema) => self.schema = Some(schema),
                Err(BadBody { reason, detail }) => {
                    let detail = format!("version {}: {detail}", snapshot.version);
                    self.rejects.record(&format!("weights/{reason}"), &detail, Instant::now());
                    return false;
                }
            }
        }
        let learner_step = snapshot.learner_step;
        match self.store.offer(snapshot) {
            Ok(version) => {
                self.counts.snapshots_accepted += 1;
                self.barrier.published(version);
                self.learner_reached(learner_step, "weights");
                true
            }
            Err(Rejected::Repeated { .. }) => {
                self.counts.snapshots_repeated += 1;
                false
            }
            Err(Rejected::NotNewer { version, held }) => {
                let detail = format!("version {version} is not newer than {held}");
                self.rejects.record("weights/not_newer", &detail, Instant::now());
                false
            }
        }
    }

    /// A frame from `control/learner`. Returns whether the global step moved.
    pub fn on_learner_step(&mut self, bytes: &[u8]) -> bool {
        match proto::decode::<LearnerStep>(bytes) {
            Ok(step) => {
                self.counts.learner_steps += 1;
                self.starvation.learner(step.starved, Instant::now());
                let moved = self.learner_reached(step.learner_step, "learner_step");
                moved | self.break_starvation()
            }
            Err(error) => {
                self.rejects.decode_failed("learner_step", &error);
                false
            }
        }
    }

    /// A frame from `control/barrier/<key_id>` (`None`: the key did not parse).
    pub fn on_barrier_report(&mut self, key_id: Option<u32>, bytes: &[u8]) {
        match proto::decode::<BarrierReport>(bytes) {
            Ok(report) if key_id == Some(report.executor_id) => {
                self.counts.barrier_reports += 1;
                if !self.barrier.report(report) {
                    self.counts.reports_from_unknown += 1;
                }
                self.note_barrier();
            }
            Ok(report) => {
                let detail = format!("report of executor {} on key {key_id:?}", report.executor_id);
                self.rejects.record("barrier/wrong_key", &detail, Instant::now());
            }
            Err(error) => self.rejects.decode_failed("barrier", &error),
        }
    }

    /// An executor's liveliness token appeared (`alive`) or vanished. Returns whether the barrier changed.
    pub fn on_liveliness(&mut self, executor: u32, alive: bool) -> bool {
        let changed = if alive { self.barrier.joined(executor) } else { self.barrier.left(executor) };
        self.note_barrier();
        if changed && alive {
            self.counts.executors_joined += 1;
            tracing::info!(executor, live = self.barrier.executors(), "executor joined");
        } else if changed {
            self.counts.executors_left += 1;
            tracing::warn!(
                executor,
                live = self.barrier.executors(),
                "executor left; its share goes to the rest"
            );
        }
        changed
    }

    fn note_barrier(&mut self) {
        self.starvation.barrier(self.barrier.all_at_barrier(), Instant::now());
    }

    /// A starved learner with every executor waiting at the barrier is a deadlock (the replay
    /// server came back empty): grant a fresh warm-up share once both have lasted a while (see
    /// [`StarvationWatch`]). Returns whether the announcement changed.
    pub fn break_starvation(&mut self) -> bool {
        self.note_barrier();
        if !self.starvation.refill_due(Instant::now()) {
            return false;
        }
        let share = self.barrier.refill();
        self.counts.refills += 1;
        tracing::warn!(share, "learner starved while every executor waits: granting a fresh warm-up share");
        true
    }

    /// One weights query answered, with `bytes` of weights (0 for an error).
    pub fn served(&mut self, bytes: usize) {
        self.counts.weights_served += 1;
        self.counts.weights_served_bytes += bytes as u64;
    }

    /// One weights version of `bytes` pushed on `params/stream`.
    pub fn pushed(&mut self, bytes: usize) {
        self.counts.weights_pushed += 1;
        self.counts.weights_pushed_bytes += bytes as u64;
    }

    /// What `control/step` says now.
    pub fn announcement(&self) -> GlobalStep {
        self.barrier.announcement()
    }

    /// Counters.
    pub fn counts(&self) -> StateCounts {
        self.counts
    }

    /// Rejections.
    pub fn rejects(&self) -> &Rejects {
        &self.rejects
    }

    /// The stats report: the global step, and the barrier of every executor with what blocks it.
    pub fn stats(&self, node: NodeId, unix_ms: u64) -> StatsReport {
        let step = self.announcement();
        let mut r = StatsReport::new(node, unix_ms);
        let c = self.counts;
        r.push_metric("param/learner_step", step.learner_step as f64);
        r.push_metric("param/weights_version", step.weights_version as f64);
        r.push_metric("param/min_weights_version", step.min_weights_version as f64);
        r.push_metric("param/warm_up_share", step.warm_up_share as f64);
        r.push_metric("param/live_executors", f64::from(step.live_executors));
        r.push_metric("param/weights_bytes", self.store.latest().map_or(0, |s| s.safetensors.len()) as f64);
        r.push_metric("param/snapshots_accepted", c.snapshots_accepted as f64);
        r.push_metric("param/snapshots_repeated", c.snapshots_repeated as f64);
        r.push_metric("param/weights_served", c.weights_served as f64);
        r.push_metric("param/weights_served_bytes", c.weights_served_bytes as f64);
        r.push_metric("param/weights_pushed", c.weights_pushed as f64);
        r.push_metric("param/weights_pushed_bytes", c.weights_pushed_bytes as f64);
        r.push_metric("param/executors_left", c.executors_left as f64);
        r.push_metric("param/refills", c.refills as f64);
        if let Some(since) = self.starvation.starved_since(Instant::now()) {
            r.blocked.push(BlockedReason {
                what: "param/learner_starved".into(),
                why: format!("the learner has waited for data for {} s", since.elapsed().as_secs()),
                since_ms: unix_ms.saturating_sub(since.elapsed().as_millis() as u64),
            });
        }
        let still_s = self.learner_moved_at.elapsed().as_secs();
        let mut blocked_executors = 0;
        for (id, report) in self.barrier.reports() {
            let Some(rep) = report else { continue };
            let prefix = format!("param/executor.{id}");
            r.push_metric(format!("{prefix}.env_steps"), rep.env_steps as f64);
            r.push_metric(format!("{prefix}.allowed_env_steps"), rep.allowed_env_steps as f64);
            r.push_metric(
                format!("{prefix}.weights_lag"),
                step.weights_version.saturating_sub(rep.weights_version) as f64,
            );
            r.push_metric(format!("{prefix}.blocked_ms_total"), rep.blocked_ms_total as f64);
            r.push_metric(format!("{prefix}.blocked"), if rep.blocked { 1.0 } else { 0.0 });
            blocked_executors += u32::from(rep.blocked);
        }
        if self.store.latest().is_none() {
            r.blocked.push(BlockedReason {
                what: "param/weights".into(),
                why: "no weights published by the learner yet".into(),
                since_ms: unix_ms,
            });
        }
        if blocked_executors > 0 && still_s >= 2 {
            let why = if step.learner_step == 0 {
                format!(
                    "{blocked_executors} executors used their warm-up share of {} and the learner has not stepped yet",
                    step.warm_up_share
                )
            } else {
                format!(
                    "{blocked_executors} executors wait at the barrier; the learner has not moved from step {} for {still_s} s",
                    step.learner_step
                )
            };
            r.blocked.push(BlockedReason { what: "param/barrier".into(), why, since_ms: unix_ms });
        }
        r.rejected = self.rejects.to_report();
        r
    }
}

#[cfg(test)]
mod tests {
    use proto::{Message, Role};

    use super::*;

    fn rule() -> BarrierRule {
        BarrierRule { env_steps_per_learner_step: 1, warm_up_transitions: 100, max_weight_lag: None }
    }

    /// A safetensors body with one `[rows, 2]` tensor of `value`s.
    fn body(rows: usize, value: f32) -> Vec<u8> {
        let data: Vec<u8> = std::iter::repeat_n(value.to_le_bytes(), rows * 2).flatten().collect();
        let view =
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![rows, 2], &data).unwrap();
        safetensors::serialize([("policy.w", view)], None).unwrap()
    }

    fn weights_with(version: u64, safetensors: Vec<u8>) -> Vec<u8> {
        proto::encode(&WeightsSnapshot { version, learner_step: version, safetensors, stack: None })
    }

    fn weights(version: u64) -> Vec<u8> {
        weights_with(version, body(3, 0.5))
    }

    #[test]
    fn bodies_that_do_not_parse_or_fit_are_refused_and_never_served() {
        let mut s = State::new(rule());
        assert!(s.on_weights(&weights(10)));
        // Well-formed frames with a newer version: a body that is not safetensors (a header length
        // beyond the body, as once forged), other shapes, a NaN. None becomes the latest.
        let mut forged = vec![0xff; 8];
        forged.extend_from_slice(b"{}");
        assert!(!s.on_weights(&weights_with(20, forged)));
        assert!(!s.on_weights(&weights_with(21, body(4, 0.5))));
        assert!(!s.on_weights(&weights_with(22, body(3, f32::NAN))));
        assert_eq!(s.announcement().weights_version, 10);
        let counts = s.rejects().counts();
        assert_eq!(
            (
                counts["weights/bad_safetensors"],
                counts["weights/schema_mismatch"],
                counts["weights/non_finite"]
            ),
            (1, 1, 1)
        );
        // The run goes on: the next good snapshot is taken.
        assert!(s.on_weights(&weights(30)));
        assert_eq!(s.announcement().weights_version, 30);
    }

    #[test]
    fn with_the_run_s_schema_a_forged_first_frame_pins_nothing() {
        let run_schema: Schema = [("policy.w".to_string(), vec![3, 2])].into();
        let mut s = State::new(rule()).with_schema(run_schema);
        // A well-formed frame of other networks arrives before the learner's: refused, not adopted.
        assert!(!s.on_weights(&weights_with(1 << 40, body(4, 0.5))));
        assert_eq!(s.rejects().counts()["weights/schema_mismatch"], 1);
        assert!(s.on_weights(&weights(10)));
        assert_eq!(s.announcement().weights_version, 10);
        // Without it, the first frame taken sets the schema, and the learner's would be refused.
        let mut pinned = State::new(rule());
        assert!(pinned.on_weights(&weights_with(5, body(4, 0.5))));
        assert!(!pinned.on_weights(&weights(10)));
    }

    #[test]
    fn in_a_hierarchy_only_weights_trained_on_its_frozen_levels_are_taken() {
        let ours = ContentHash([1; 32]);
        let stamped = |version, stack| {
            proto::encode(&WeightsSnapshot {
                version,
                learner_step: version,
                safetensors: body(3, 0.5),
                stack,
            })
        };
        let mut s = State::new(rule()).with_stack(ours);
        assert!(!s.on_weights(&stamped(10, None)), "a single-level learner's");
        assert!(!s.on_weights(&stamped(11, Some(ContentHash([2; 32])))), "another stack's");
        assert_eq!(s.rejects().counts()["weights/stack_mismatch"], 2);
        assert!(s.on_weights(&stamped(12, Some(ours))));
        assert_eq!(s.announcement().weights_version, 12);
        // And a single-level run refuses weights of a hierarchy.
        let mut single = State::new(rule());
        assert!(!single.on_weights(&stamped(10, Some(ours))));
        assert!(single.on_weights(&stamped(11, None)));
    }

    #[test]
    fn weights_and_steps_move_the_announcement_forward_only() {
        let mut s = State::new(rule());
        assert!(s.on_weights(&weights(0)));
        assert!(!s.on_weights(&weights(0)), "a repeat is not newer");
        assert!(s.on_weights(&weights(50)));
        assert!(!s.on_weights(&weights(20)), "older");
        assert_eq!(s.announcement().weights_version, 50);
        assert_eq!(s.announcement().learner_step, 50, "the snapshot's learner step counts too");
        assert!(s.on_learner_step(&proto::encode(&LearnerStep {
            learner_step: 60,
            weights_version: 50,
            starved: false
        })));
        assert!(!s.on_learner_step(&proto::encode(&LearnerStep {
            learner_step: 55,
            weights_version: 50,
            starved: false
        })));
        assert_eq!(s.announcement().learner_step, 60);
        assert_eq!(s.rejects().counts()["weights/not_newer"], 1, "the repeat is not bad input");
        assert_eq!(s.counts().snapshots_repeated, 1);
    }

    #[test]
    fn a_forged_learner_step_of_2_to_the_62_does_not_pin_the_global_step() {
        let mut s = State::new(rule()).with_step_guard(StepGuard::new(1000));
        let step =
            |learner_step| proto::encode(&LearnerStep { learner_step, weights_version: 0, starved: false });
        assert!(s.on_learner_step(&step(100)));
        assert!(!s.on_learner_step(&step(1 << 62)), "refused");
        assert_eq!(s.announcement().learner_step, 100);
        assert_eq!(s.rejects().counts()["learner_step/implausible_step"], 1);
        // The real learner's next steps still move it.
        assert!(s.on_learner_step(&step(600)));
        assert_eq!(s.announcement().learner_step, 600);
    }

    #[test]
    fn bad_frames_are_counted_by_reason_and_change_nothing() {
        let mut s = State::new(rule());
        assert!(!s.on_weights(b"garbage"));
        let mut corrupt = weights(5);
        let last = corrupt.len() - 1;
        corrupt[last] ^= 0xFF;
        assert!(!s.on_weights(&corrupt));
        assert!(!s.on_learner_step(&weights(5)), "wrong kind");
        let report = BarrierReport {
            executor_id: 3,
            env_steps: 10,
            allowed_env_steps: 25,
            learner_step_seen: 0,
            joined_at: 0,
            weights_version: 0,
            blocked: true,
            blocked_ms_total: 5,
        };
        s.on_barrier_report(Some(4), &proto::encode(&report));
        assert_eq!(s.announcement().live_executors, 0);
        let counts = s.rejects().counts();
        assert_eq!(counts["weights/truncated"], 1);
        assert_eq!(counts["weights/checksum"], 1);
        assert_eq!(counts["learner_step/wrong_kind"], 1);
        assert_eq!(counts["barrier/wrong_key"], 1);
        assert_eq!(s.announcement().weights_version, 0);
    }

    #[test]
    fn liveliness_sets_the_share_and_stats_show_each_executor() {
        let mut s = State::new(rule());
        assert!(s.on_liveliness(0, true));
        assert!(s.on_liveliness(1, true));
        assert!(!s.on_liveliness(1, true));
        assert_eq!(s.announcement().warm_up_share, 50);
        let report = BarrierReport {
            executor_id: 1,
            env_steps: 50,
            allowed_env_steps: 50,
            learner_step_seen: 0,
            joined_at: 0,
            weights_version: 0,
            blocked: true,
            blocked_ms_total: 5,
        };
        s.on_barrier_report(Some(1), &proto::encode(&report));
        let stats = s.stats(NodeId { role: Role::Param, id: 0 }, 1);
        assert_eq!(stats.validate(), Ok(()));
        assert_eq!(stats.metric("param/executor.1.blocked"), Some(1.0));
        assert_eq!(stats.metric("param/live_executors"), Some(2.0));
        assert!(stats.blocked.iter().any(|b| b.what == "param/weights"));
        assert!(s.on_liveliness(0, false));
        assert_eq!(s.announcement().warm_up_share, 100);
    }
}
