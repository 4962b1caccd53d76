//! What the manager counts for a run's summary: requests, latencies, needs met,
//! stale frames and why, draws, and where each frame's time went.

use std::time::Instant;

/// What a run counted: the demo's summary and the load test's rows are made of these.
#[derive(Debug, Clone, Default)]
pub struct Counters {
    /// Impostors redrawn as sprites (no warp) and impostors warped.
    pub sprites: u64,
    pub warps: u64,
    /// Partners warped (second textures drawn behind the shown one).
    pub partners: u64,
    pub requests_now: u64,
    pub requests_predicted: u64,
    pub withdrawn: u64,
    /// Requests that ended without their texture: refused or broken off …
    pub requests_failed: u64,
    /// … or unanswered within their deadline (and withdrawn) …
    pub requests_timed_out: u64,
    /// … or predictions the saturated server refused.
    pub requests_shed: u64,
    /// Final textures one placement asked for and another placement of its mesh was
    /// given too (a request it did not make).
    pub textures_shared: u64,
    /// The factor the server's load put on the tolerance, summed over the frames drawn
    /// (over their count: its mean; see [`LOAD_HIGH_WAIT`](super::policy::LOAD_HIGH_WAIT)).
    pub load_scale_sum: f64,
    /// The factor the link put on it, summed likewise (see
    /// [`Manager::link_scale`](super::Manager::link_scale)).
    pub link_scale_sum: f64,
    /// Request sent → final texture received by the client, milliseconds …
    pub latencies_ms: Vec<f64>,
    /// … of the requests needed now alone (a frame waits on them) …
    pub latencies_now_ms: Vec<f64>,
    /// … and of the predicted ones, their texture's arrival against the time it was
    /// predicted to be needed, milliseconds: late when positive. (A prediction is
    /// asked for a round trip ahead: its latency is long by design, its lateness is
    /// what a frame sees.)
    pub prediction_lateness_ms: Vec<f64>,
    /// Final texture received → taken in by a frame (made ready, and the frame loop
    /// come round), milliseconds.
    pub pickup_ms: Vec<f64>,
    /// The lifetimes of the final textures no longer held (with those still held:
    /// [`Manager::texture_lifetimes`](super::Manager::texture_lifetimes)).
    pub retired: TextureLifetimes,
    /// Frames × objects where a valid texture was needed (impostors that may be on
    /// screen, and objects standing in for one).
    pub needs: u64,
    /// … and one was there or already asked for.
    pub prediction_hits: u64,
    /// Frames where some impostor was shown above tolerance, alone too far from its
    /// eye, or missing (and not drawn as geometry instead: `stand_ins`).
    pub stale_frames: u64,
    /// Why: the object-frames without a valid texture, by cause (those drawn as
    /// geometry instead, `stand_ins`, left out).
    pub stale_causes: StaleCauses,
    /// Object-frames without a valid texture drawn exactly as geometry instead, nearest
    /// first, each that still fits in the frame's
    /// [`STAND_IN_TRIANGLES`](super::policy::STAND_IN_TRIANGLES): not stale, and among
    /// the `needs`. (Objects no dearer as geometry than as impostors are drawn so
    /// whatever they hold, and are in neither.)
    pub stand_ins: u64,
    /// Where each [`Manager::render`](super::Manager::render) spent its time, and the
    /// texels it warped.
    pub render_stages: Vec<RenderStages>,
}

impl Counters {
    /// Texels pre-warped over the run ([`RenderStages::texels_warped`], summed).
    pub fn texels_warped(&self) -> u64 {
        self.render_stages.iter().map(|s| s.texels_warped).sum()
    }
}

/// Of predictions' lateness ([`Counters::prediction_lateness_ms`]), the fraction
/// late; NaN (`null` in JSON) for none.
pub fn late_fraction(lateness_ms: &[f64]) -> f64 {
    lateness_ms.iter().filter(|&&ms| ms > 0.0).count() as f64 / lateness_ms.len() as f64
}

/// How long final textures served: seconds from each one's arrival to the last frame
/// it was shown in, and how many were never shown.
#[derive(Debug, Clone, Default)]
pub struct TextureLifetimes {
    pub seconds: Vec<f64>,
    pub never_shown: u64,
    /// Of those never shown, how many whose object was shown from its other textures
    /// after a frame took them in: another was chosen. The rest were not chosen because
    /// the object was not shown as an impostor again: off screen, drawn as geometry,
    /// or the run ended first (a view asked for that did not come).
    pub superseded: u64,
}

impl TextureLifetimes {
    /// Counts the lifetime of `held`, a texture no longer held or counted as such
    /// (previews are not counted), of an object last shown (from any texture) at
    /// `object_shown`.
    pub(super) fn retire(&mut self, held: &super::cache::Held, object_shown: Option<Instant>) {
        if !held.is_final || held.shared {
            return;
        }
        match held.last_shown {
            Some(shown) => self
                .seconds
                .push(shown.saturating_duration_since(held.arrived).as_secs_f64()),
            None => {
                self.never_shown += 1;
                self.superseded += u64::from(object_shown.is_some_and(|shown| shown > held.taken_in));
            }
        }
    }
}

/// Object-frames without a valid texture, by cause (the first that applies).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StaleCauses {
    /// No held texture can be warped to the eye at all: none held yet, or all too far
    /// round the object (past [`MAX_TURN`](super::policy::MAX_TURN)) or at too
    /// different a distance.
    pub missing: u64,
    /// Some can, but none that may be shown (not too coarse) within the tolerance.
    pub beyond_tolerance: u64,
    /// One within tolerance, but shown too far from its eye: alone, with no partner held
    /// to fill the side it misses, or past what even a partner can mend (see
    /// `may_show` in `choose.rs`).
    pub too_far: u64,
}

/// Where one [`Manager::render`](super::Manager::render) spent its time, milliseconds,
/// and the texels it warped.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RenderStages {
    /// Deciding which impostors are warped, and their pre-warps (all at once).
    pub prewarp_ms: f64,
    /// Impostors drawn: texture mapping of the pre-warps, and sprites redrawn.
    pub draw_ms: f64,
    /// Objects drawn as geometry (cheap ones, too-near ones, failed warps).
    pub geometry_ms: f64,
    /// Lighting the G-buffer into the frame.
    pub shade_ms: f64,
    /// Texels pre-warped, over all warps and partners (each at its pyramid level for
    /// the screen; of those, the ones that can reach the screen): what the frame's
    /// impostors cost.
    pub texels_warped: u64,
}
