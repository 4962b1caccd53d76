//! Finished textures kept for reuse, bounded in bytes: a request a cached texture
//! satisfies is answered at once; the least recently used goes first.

use std::sync::Arc;

use relief_proto::pb;

use super::State;
use super::jobs::JobKey;

/// A finished texture kept for reuse.
#[derive(Debug)]
pub(super) struct Cached {
    pub(super) key: JobKey,
    pub(super) texture: Arc<pb::ReliefTexture>,
    pub(super) bytes: usize,
    pub(super) used: u64,
}

impl State {
    /// The smallest cached texture that serves `wanted`.
    pub(super) fn cached_for(&mut self, wanted: &JobKey) -> Option<&mut Cached> {
        self.cache
            .get_mut(&wanted.view)?
            .iter_mut()
            .filter(|c| c.key.satisfies(wanted))
            .min_by_key(|c| c.bytes)
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
        let entries = self.cache.entry(entry.key.view.clone()).or_default();
        match entries.iter_mut().find(|c| c.key == entry.key) {
            Some(old) => {
                self.cache_bytes -= old.bytes;
                self.recency.remove(&old.used);
                *old = entry;
            }
            None => entries.push(entry),
        }
        self.cache_bytes += bytes;
        // Least recently used first (the one just put in is the most recent, and fits
        // alone).
        while self.cache_bytes > self.limits.cache_bytes {
            let Some((_, key)) = self.recency.pop_first() else {
                break;
            };
            if let Some(entries) = self.cache.get_mut(&key.view) {
                if let Some(k) = entries.iter().position(|c| c.key == key) {
                    self.cache_bytes -= entries.swap_remove(k).bytes;
                }
                if entries.is_empty() {
                    self.cache.remove(&key.view);
                }
            }
        }
    }
}
