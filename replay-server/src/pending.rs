//! Blocked sample requests, sans-IO: a bounded FIFO with one deadline per request. The server keeps
//! the zenoh `Query` in `T`; tests use plain numbers.
//!
//! Requests are served in arrival order: a later request is not served before an earlier one, so a
//! learner with several requests in flight gets its replies in order, and deadlines (arrival plus a
//! fixed delay) are sorted too, which makes expiry a pop from the front.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use proto::SampleRequest;

use crate::limiter::Blocked;

/// One blocked request.
#[derive(Debug)]
pub struct Waiter<T> {
    /// What the server needs to answer it (the zenoh query).
    pub ticket: T,
    /// The request.
    pub request: SampleRequest,
    /// When it arrived.
    pub arrived: Instant,
    /// When it must be answered, served or not.
    pub deadline: Instant,
    /// Why it waits (the latest check).
    pub blocked: Blocked,
}

/// The queue of blocked requests.
#[derive(Debug)]
pub struct Pending<T> {
    queue: VecDeque<Waiter<T>>,
    capacity: usize,
    wait: Duration,
}

impl<T> Pending<T> {
    /// A queue of at most `capacity` requests, each waiting at most `wait`.
    pub fn new(capacity: usize, wait: Duration) -> Self {
        Self { queue: VecDeque::new(), capacity, wait }
    }

    /// Queues a request that arrived at `now`; hands it back when the queue is full.
    pub fn push(
        &mut self,
        ticket: T,
        request: SampleRequest,
        blocked: Blocked,
        now: Instant,
    ) -> Result<(), T> {
        if self.queue.len() >= self.capacity {
            return Err(ticket);
        }
        self.queue.push_back(Waiter { ticket, request, arrived: now, deadline: now + self.wait, blocked });
        Ok(())
    }

    /// The oldest request.
    pub fn front(&self) -> Option<&Waiter<T>> {
        self.queue.front()
    }

    /// Records a new reason for the oldest request.
    pub fn set_front_blocked(&mut self, blocked: Blocked) {
        if let Some(front) = self.queue.front_mut() {
            front.blocked = blocked;
        }
    }

    /// Removes the oldest request.
    pub fn pop_front(&mut self) -> Option<Waiter<T>> {
        self.queue.pop_front()
    }

    /// Removes every request whose deadline is at or before `now`.
    pub fn expire(&mut self, now: Instant) -> Vec<Waiter<T>> {
        let due = self.queue.iter().take_while(|w| w.deadline <= now).count();
        self.queue.drain(..due).collect()
    }

    /// Removes every request (at shutdown).
    pub fn drain_all(&mut self) -> Vec<Waiter<T>> {
        self.queue.drain(..).collect()
    }

    /// The earliest deadline, if anything waits.
    pub fn next_deadline(&self) -> Option<Instant> {
        self.queue.front().map(|w| w.deadline)
    }

    /// Requests waiting.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Nothing waits.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(id: u64) -> SampleRequest {
        SampleRequest { request_id: id, learner_step: 0, batch_size: 8 }
    }

    const BLOCKED: Blocked = Blocked::BelowMinSize { have: 0, min: 10 };

    #[test]
    fn bounded_fifo_with_sorted_deadlines() {
        let t0 = Instant::now();
        let mut pending = Pending::new(2, Duration::from_millis(100));
        pending.push(1, request(1), BLOCKED, t0).unwrap();
        pending.push(2, request(2), BLOCKED, t0 + Duration::from_millis(30)).unwrap();
        assert_eq!(pending.push(3, request(3), BLOCKED, t0), Err(3), "full");
        assert_eq!(pending.next_deadline(), Some(t0 + Duration::from_millis(100)));
        assert!(pending.expire(t0 + Duration::from_millis(99)).is_empty());
        let expired = pending.expire(t0 + Duration::from_millis(100));
        assert_eq!(expired.iter().map(|w| w.ticket).collect::<Vec<_>>(), [1]);
        assert_eq!(pending.front().map(|w| w.request.request_id), Some(2));
        pending.set_front_blocked(Blocked::BelowMinSize { have: 5, min: 10 });
        assert_eq!(pending.front().map(|w| w.blocked.missing_inserts()), Some(5));
        assert_eq!(pending.drain_all().len(), 1);
        assert!(pending.is_empty() && pending.next_deadline().is_none());
    }
}
