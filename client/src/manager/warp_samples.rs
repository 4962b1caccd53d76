//! Pre-warps a flight made, kept to be timed again on their own: about one in K, with
//! the texture level each warped and the camera (in the object's frame) it warped it
//! for.
//!
//! A bench's one texture seen a few degrees from its eye flatters the pre-warp: a
//! flight shows leaves, rough rocks and textures turned further, which take their
//! passes' scalar steps. `relief demo --warp-samples K` writes what this keeps, and
//! `relief bench replay` times each again, alone: the flight's own work, to compare
//! builds on, apart from what else the flight's frames did.
//!
//! The textures are shared, not copied, so keeping a sample costs its frame nothing;
//! but a kept texture stays alive past the cache's eviction, and one that arrives
//! again is then not made ready anew (see [`crate::intake`]): a sampled flight's
//! intake differs that little from another's.

use std::collections::HashSet;
use std::sync::Arc;

use relief_core::camera::Camera;
use relief_core::generators::SplitMix64;
use relief_render::impostor::Impostor;

use super::Prepared;
use super::policy::{MAX_WARP_SAMPLE_TEXELS, MAX_WARP_SAMPLES};

/// One pre-warp of a frame, as [`Manager::render`](super::Manager::render) made it.
#[derive(Clone)]
pub struct WarpSample {
    /// The object's index in the scene.
    pub object: usize,
    /// The camera of the frame, in the object's frame (what the pre-warp was given).
    pub camera: Camera,
    /// Whether the texture was the object's partner, drawn behind the first.
    pub partner: bool,
    /// Texels the pre-warp visited ([`Prewarped::texels_warped`](relief_render::warp::Prewarped::texels_warped)).
    pub visited: usize,
    /// Its wall time in the frame, ms. On one thread, the pre-warp's own; on more, a
    /// pre-warp waiting at its halves' join runs other work meanwhile, and this counts
    /// it.
    pub in_frame_ms: f64,
    /// The texture (shared, not copied: keeping a sample costs the frame nothing) and
    /// the level of its pyramid warped.
    pub(super) prepared: Arc<Prepared>,
    pub(super) level: usize,
}

impl WarpSample {
    /// The pyramid level the pre-warp warped.
    pub fn impostor(&self) -> &Impostor {
        &self.prepared.pyramid.levels[self.level]
    }
}

/// Which pre-warps are kept: about one in `every`, chosen by a fixed pseudo-random
/// sequence (a frame warps its objects in one order, so every K-th alone could keep
/// meeting the same object), while the samples stay within [`MAX_WARP_SAMPLES`] and their textures
/// within [`MAX_WARP_SAMPLE_TEXELS`].
pub(super) struct WarpSampler {
    every: u64,
    /// One draw a pre-warp: kept where it is a multiple of `every`.
    draws: SplitMix64,
    pub(super) kept: Vec<WarpSample>,
    /// The textures the samples hold, by address (unique while they are held), and
    /// their texels.
    held: HashSet<usize>,
    held_texels: usize,
    /// Pre-warps chosen but not kept, the limits reached.
    pub(super) left_out: usize,
}

impl WarpSampler {
    /// Keeps about one in `every` pre-warps from the next on (`every` ≥ 1).
    pub(super) fn new(every: u32) -> WarpSampler {
        WarpSampler {
            every: u64::from(every.max(1)),
            draws: SplitMix64::new(0),
            kept: Vec::new(),
            held: HashSet::new(),
            held_texels: 0,
            left_out: 0,
        }
    }

    /// Counts one pre-warp of `prepared`: whether it is kept (then the caller pushes
    /// its sample).
    pub(super) fn keeps(&mut self, prepared: &Arc<Prepared>) -> bool {
        if !self.draws.next_u64().is_multiple_of(self.every) {
            return false;
        }
        let address = Arc::as_ptr(prepared) as usize;
        let texels = match self.held.contains(&address) {
            true => 0,
            false => prepared.pyramid.levels[0].texture.depth.len(),
        };
        if self.kept.len() >= MAX_WARP_SAMPLES || self.held_texels + texels > MAX_WARP_SAMPLE_TEXELS {
            self.left_out += 1;
            return false;
        }
        self.held.insert(address);
        self.held_texels += texels;
        true
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    /// About one in K is kept, for a K that divides a frame's count of pre-warps as
    /// well as one that does not; and the choice falls on every position in a frame.
    #[test]
    fn about_one_in_k_is_kept_from_every_position() {
        for every in [1u64, 3, 4, 10] {
            let mut draws = SplitMix64::new(0);
            let kept: Vec<u64> = (0..30_000)
                .filter(|_| draws.next_u64().is_multiple_of(every))
                .collect();
            let expected = 30_000 / every as usize;
            assert!(
                kept.len().abs_diff(expected) * 20 < expected,
                "one in {every}: {}",
                kept.len()
            );
            // Frames of 3 pre-warps: each position is kept.
            for position in 0..3 {
                assert!(
                    kept.iter().any(|n| n % 3 == position),
                    "one in {every}, position {position}"
                );
            }
        }
    }
}
