//! Pre-warps a flight made, kept to be timed again on their own: every K-th, with the
//! texture level it warped and the camera (in the object's frame) it warped it for.
//!
//! A bench's one texture seen a few degrees from its eye flatters the pre-warp: a
//! flight shows leaves, rough rocks and textures turned further, which take their
//! passes' scalar steps. `relief demo --warp-samples K` writes what this keeps, and
//! `relief bench replay` times each again, alone: the flight's own work, to compare
//! builds on, apart from what else the flight's frames did.

use std::sync::Arc;

use relief_core::camera::Camera;
use relief_render::impostor::Impostor;

use super::Prepared;
use super::policy::MAX_WARP_SAMPLES;

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
    /// The frame's pre-warp time for it, ms: beside the frame's other pre-warps,
    /// on the frame's threads.
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

/// Which pre-warps are kept: every `every`-th, up to [`MAX_WARP_SAMPLES`].
pub(super) struct WarpSampler {
    every: u64,
    seen: u64,
    pub(super) kept: Vec<WarpSample>,
}

impl WarpSampler {
    /// Keeps every `every`-th pre-warp from the next on (`every` ≥ 1).
    pub(super) fn new(every: u32) -> WarpSampler {
        WarpSampler {
            every: u64::from(every.max(1)),
            seen: 0,
            kept: Vec::new(),
        }
    }

    /// Counts one pre-warp: whether it is kept.
    pub(super) fn keeps_next(&mut self) -> bool {
        let keep = self.seen.is_multiple_of(self.every) && self.kept.len() < MAX_WARP_SAMPLES;
        self.seen += 1;
        keep
    }
}
