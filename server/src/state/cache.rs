//! Finished textures kept for reuse, bounded in bytes and in textures per subject
//! ([`SUBJECT_SCAN`]): a request a cached texture serves is answered at once; the least
//! recently used goes first.

use std::sync::Arc;

use relief_proto::pb;

use super::State;
use super::jobs::{JobKey, SUBJECT_SCAN, Wanted};

/// A finished texture kept for reuse.
#[derive(Debug)]
pub(super) struct Cached {
    pub(super) key: JobKey,
    pub(super) texture: Arc<pb::ReliefTexture>,
    pub(super) bytes: usize,
    pub(super) used: u64,
}

impl State {
    /// The cached texture that serves `wanted` from the eye nearest its own, the
    /// smallest of those.
    pub(super) fn cached_for(&mut self, wanted: &Wanted) -> Option<&mut Cached> {
        self.cache
            .get_mut(&wanted.key.subject)?
            .iter_mut()
            .filter_map(|c| Some((c.key.serves(wanted)?, c)))
            .min_by(|(a, c), (b, d)| a.total_cmp(b).then(c.bytes.cmp(&d.bytes)))
            .map(|(_, c)| c)
    }

    pub(super) fn cache_insert(&mut self, key: JobKey, texture: Arc<pb::ReliefTexture>, bytes: usize) {
        if bytes > self.limits.cache_bytes {
            return;
        }
        self.clock += 1;
        let entry = Cached {
            key,
            texture,
            bytes,
            used: self.clock,
        };
        self.recency.insert(self.clock, entry.key.clone());
        let entries = self.cache.entry(entry.key.subject.clone()).or_default();
        match entries.iter_mut().find(|c| c.key == entry.key) {
            Some(old) => {
                self.cache_bytes -= old.bytes;
                self.recency.remove(&old.used);
                *old = entry;
            }
            None => entries.push(entry),
        }
        self.cache_bytes += bytes;
        // The subject's least recently used past its bound.
        if entries.len() > SUBJECT_SCAN
            && let Some(k) = (0..entries.len()).min_by_key(|&k| entries[k].used)
        {
            let gone = entries.swap_remove(k);
            self.cache_bytes -= gone.bytes;
            self.recency.remove(&gone.used);
        }
        // Least recently used first (the one just put in is the most recent, and fits
        // alone).
        while self.cache_bytes > self.limits.cache_bytes {
            let Some((_, key)) = self.recency.pop_first() else {
                break;
            };
            if let Some(entries) = self.cache.get_mut(&key.subject) {
                if let Some(k) = entries.iter().position(|c| c.key == key) {
                    self.cache_bytes -= entries.swap_remove(k).bytes;
                }
                if entries.is_empty() {
                    self.cache.remove(&key.subject);
                }
            }
        }
    }
}
