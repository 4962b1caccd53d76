//! The scenes stored: each one's bundle (what workers fetch) and its objects' bounds,
//! who uploaded it, and when it was last used — bounded in bytes, the least recently
//! used scene no job needs evicted first.

use std::collections::{HashMap, HashSet};
use std::sync::Arc;

use relief_core::bounds::Aabb;
use relief_core::hash::ContentHash;

use super::State;

/// A stored scene: its encoded bundle and, by name, its objects' bounds and meshes
/// (enough to check requests without loading meshes again).
#[derive(Debug)]
pub struct StoredScene {
    pub encoded: Arc<Vec<u8>>,
    pub objects: HashMap<String, StoredObject>,
}

/// What the server knows of one object of a stored scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoredObject {
    /// Its bounds, in its own frame.
    pub bounds: Aabb,
    /// Its mesh's content hash: placements of one mesh share textures (one eye in the
    /// object's frame sees the same of each).
    pub mesh: ContentHash,
}

/// Why a scene is not stored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SceneRefusal {
    #[error(
        "the scene's bundle is {bytes} bytes, more than the server stores ({limit} bytes: --scene-store-mb)"
    )]
    TooLarge { bytes: usize, limit: usize },
    #[error(
        "the server's scene store ({limit} bytes: --scene-store-mb) is full of scenes that jobs still need"
    )]
    Full { limit: usize },
}

#[derive(Debug)]
struct Entry {
    scene: Arc<StoredScene>,
    /// The clients (by [`Caller`](crate::identity::Caller) name) that uploaded it:
    /// only they may read it or ask for its textures.
    owners: HashSet<Arc<str>>,
    /// [`Scenes::clock`] when it was last stored, asked for or fetched.
    used: u64,
}

/// Every stored scene and the bytes they take.
#[derive(Debug, Default)]
pub(super) struct Scenes {
    stored: HashMap<ContentHash, Entry>,
    bytes: usize,
    clock: u64,
}

impl Scenes {
    /// The scene `hash`, marked used now.
    fn touch(&mut self, hash: &ContentHash) -> Option<&Entry> {
        self.clock += 1;
        let entry = self.stored.get_mut(hash)?;
        entry.used = self.clock;
        Some(entry)
    }
}

impl State {
    /// Stores a scene `owner` uploaded. While the store is past
    /// [`Limits::scene_store_bytes`](super::Limits::scene_store_bytes), the least
    /// recently used scenes no job needs are evicted: their hashes are returned (their
    /// files are the caller's to remove). A scene larger than the store, or one that
    /// only scenes still needed keep out, is refused, and nothing is evicted for it.
    pub fn add_scene(
        &mut self,
        hash: ContentHash,
        scene: StoredScene,
        owner: &Arc<str>,
    ) -> Result<Vec<ContentHash>, SceneRefusal> {
        if self.scenes.stored.contains_key(&hash) {
            self.add_owner(hash, owner);
            return Ok(Vec::new());
        }
        let (bytes, limit) = (scene.encoded.len(), self.limits.scene_store_bytes);
        if bytes > limit {
            return Err(SceneRefusal::TooLarge { bytes, limit });
        }
        let needed: HashSet<ContentHash> = self.jobs.values().map(|job| job.key.subject.scene).collect();
        let mut idle: Vec<(u64, ContentHash, usize)> = (self.scenes.stored.iter())
            .filter(|(h, _)| !needed.contains(*h))
            .map(|(h, e)| (e.used, *h, e.scene.encoded.len()))
            .collect();
        let idle_bytes: usize = idle.iter().map(|(_, _, b)| b).sum();
        if self.scenes.bytes - idle_bytes + bytes > limit {
            return Err(SceneRefusal::Full { limit });
        }
        idle.sort_unstable();
        let mut evicted = Vec::new();
        for (_, old, old_bytes) in idle {
            if self.scenes.bytes + bytes <= limit {
                break;
            }
            self.scenes.stored.remove(&old);
            self.scenes.bytes -= old_bytes;
            evicted.push(old);
        }
        self.scenes.clock += 1;
        self.scenes.bytes += bytes;
        self.scenes.stored.insert(
            hash,
            Entry {
                scene: Arc::new(scene),
                owners: HashSet::from([owner.clone()]),
                used: self.scenes.clock,
            },
        );
        self.counters.scenes_evicted += evicted.len() as u64;
        Ok(evicted)
    }

    /// `owner` uploaded scene `hash`, stored already: having sent the whole content, it
    /// may read it too.
    pub fn add_owner(&mut self, hash: ContentHash, owner: &Arc<str>) {
        if let Some(entry) = self.scenes.stored.get_mut(&hash) {
            entry.owners.insert(owner.clone());
        }
    }

    /// Whether scene `hash` is stored (for anyone).
    pub fn has_scene(&self, hash: &ContentHash) -> bool {
        self.scenes.stored.contains_key(hash)
    }

    /// Bytes of the scenes stored.
    pub fn scene_bytes(&self) -> usize {
        self.scenes.bytes
    }

    /// The scene `hash`, if `owner` uploaded it (marked used).
    pub fn scene_of(&mut self, hash: &ContentHash, owner: &str) -> Option<Arc<StoredScene>> {
        if !self.scenes.stored.get(hash)?.owners.contains(owner) {
            return None;
        }
        self.scenes.touch(hash).map(|e| e.scene.clone())
    }

    /// The scene `hash`, if a worker session of `credential` holds a job on it (marked
    /// used, and its fetch noted: [`State::worker_fetches`]).
    pub fn scene_for_worker(&mut self, hash: &ContentHash, credential: &str) -> Option<Arc<StoredScene>> {
        if !self.worker_fetches(hash, credential) {
            return None;
        }
        self.scenes.touch(hash).map(|e| e.scene.clone())
    }

    /// Notes that a worker of `credential` fetches scene `hash`: the jobs on it that
    /// the credential's sessions hold wait for the scene's load, and their times are
    /// not counted as a job's (see `Job::loaded_scene`). Whether they hold any. (By
    /// credential: the fetch does not name its session, so where workers share one,
    /// all their jobs on the scene go untimed then.)
    pub fn worker_fetches(&mut self, hash: &ContentHash, credential: &str) -> bool {
        let on_it: Vec<u64> = (self.workers.values())
            .filter(|w| &*w.credential == credential)
            .flat_map(|w| w.running.iter().copied())
            .filter(|id| {
                self.jobs
                    .get(id)
                    .is_some_and(|job| job.key.subject.scene == *hash)
            })
            .collect();
        for &id in &on_it {
            if let Some(job) = self.jobs.get_mut(&id) {
                job.loaded_scene = true;
            }
        }
        !on_it.is_empty()
    }

    /// The bounds of `object` of scene `hash`, if both are stored.
    pub(super) fn object_bounds(&self, hash: &ContentHash, object: &str) -> Option<Aabb> {
        Some(self.scenes.stored.get(hash)?.scene.objects.get(object)?.bounds)
    }
}
