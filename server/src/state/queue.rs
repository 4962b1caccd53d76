//! The queue of jobs waiting for a worker, fair across clients: each client credential
//! has its own line, and a free slot goes to the most urgent head of line among the
//! clients with the fewest jobs running, the one served longest ago first — so one
//! client's flood of requests is baked turn about with another's single one, instead
//! of all before it.

use std::collections::{BTreeSet, HashMap};
use std::sync::Arc;

/// Queue order within one client's line: needed-now first, then nearest deadline, then
/// arrival.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Priority {
    pub(super) predicted: bool,
    pub(super) deadline_us: u64,
    pub(super) id: u64,
}

/// Jobs waiting, one line per client credential (the job's first asker), how many jobs
/// each client has running, and when each was last served.
#[derive(Debug, Default)]
pub(super) struct FairQueue {
    lines: HashMap<Arc<str>, BTreeSet<Priority>>,
    running: HashMap<Arc<str>, usize>,
    /// The turn ([`FairQueue::turn`]) each client with jobs waiting or running last
    /// had a job started (none yet: first in line).
    served: HashMap<Arc<str>, u64>,
    turn: u64,
}

impl FairQueue {
    pub(super) fn insert(&mut self, owner: &Arc<str>, priority: Priority) {
        self.lines.entry(owner.clone()).or_default().insert(priority);
    }

    pub(super) fn remove(&mut self, owner: &Arc<str>, priority: &Priority) {
        if let Some(line) = self.lines.get_mut(owner) {
            line.remove(priority);
            if line.is_empty() {
                self.lines.remove(owner);
                self.forget_if_idle(owner);
            }
        }
    }

    /// A client with nothing waiting or running leaves no trace.
    fn forget_if_idle(&mut self, owner: &Arc<str>) {
        if !self.lines.contains_key(owner) && !self.running.contains_key(owner) {
            self.served.remove(owner);
        }
    }

    /// The job a free slot should take: needed-now before predicted; then the client
    /// with the fewest jobs running, and of those the one served longest ago; then the
    /// nearest deadline.
    pub(super) fn next(&self) -> Option<(Arc<str>, Priority)> {
        (self.lines.iter())
            .filter_map(|(owner, line)| Some((owner, *line.first()?)))
            .min_by_key(|(owner, p)| {
                let served = self.served.get(*owner).copied().unwrap_or(0);
                (p.predicted, self.running_of(owner), served, p.deadline_us, p.id)
            })
            .map(|(owner, p)| (owner.clone(), p))
    }

    /// A job of `owner` went to a worker.
    pub(super) fn started(&mut self, owner: &Arc<str>) {
        *self.running.entry(owner.clone()).or_default() += 1;
        self.turn += 1;
        self.served.insert(owner.clone(), self.turn);
    }

    /// A running job of `owner` ended, or went back to the queue.
    pub(super) fn stopped(&mut self, owner: &Arc<str>) {
        if let Some(count) = self.running.get_mut(owner) {
            *count = count.saturating_sub(1);
            if *count == 0 {
                self.running.remove(owner);
                self.forget_if_idle(owner);
            }
        }
    }

    pub(super) fn running_of(&self, owner: &str) -> usize {
        self.running.get(owner).copied().unwrap_or(0)
    }

    /// Jobs waiting, needed-now ones (`predicted` false) or predicted ones.
    pub(super) fn count(&self, predicted: bool) -> usize {
        (self.lines.values())
            .map(|line| line.iter().filter(|p| p.predicted == predicted).count())
            .sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flood_is_served_turn_about_with_a_single_request() {
        let (flood, single): (Arc<str>, Arc<str>) = ("flood".into(), "single".into());
        let mut queue = FairQueue::default();
        let now = |deadline_us: u64, id: u64| Priority {
            predicted: false,
            deadline_us,
            id,
        };
        for id in 1..=100 {
            queue.insert(&flood, now(id, id));
        }
        queue.insert(&single, now(1_000, 1_000));
        let predicted = Priority {
            predicted: true,
            deadline_us: 0,
            id: 2_000,
        };
        queue.insert(&single, predicted);
        // Flood's first job runs; the single client's goes next, ahead of 99 earlier
        // deadlines, and its predicted one after every needed-now job.
        let mut order = Vec::new();
        // One slot: each job ends before the next starts.
        while let Some((owner, p)) = queue.next() {
            queue.remove(&owner, &p);
            queue.started(&owner);
            queue.stopped(&owner);
            order.push(p.id);
        }
        assert_eq!(&order[..3], &[1, 1_000, 2]);
        assert_eq!(order.last(), Some(&2_000));
        assert_eq!(order.len(), 102);
        assert_eq!((queue.count(false), queue.count(true)), (0, 0));
        assert!(queue.served.is_empty() && queue.running.is_empty());
    }
}
