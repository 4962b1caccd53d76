//! What `relief demo` reports: `summary.json`, and the one line it prints.

use std::collections::BTreeMap;
use std::path::Path;

use serde::Serialize;

use relief_client::flight::FrameRecord;
use relief_client::manager::{RenderStages, StaleCauses};
use relief_core::stats::median;

/// The stages of the demo's frames, milliseconds.
#[derive(Serialize)]
pub(super) struct FrameStages {
    /// The impostor manager's decisions and requests.
    plan: f64,
    /// Deciding which impostors are warped (or redrawn as sprites), and their
    /// pre-warps.
    prewarp: f64,
    /// Impostors drawn: pre-warps texture-mapped, sprites redrawn.
    draw: f64,
    /// Objects drawn as geometry.
    geometry: f64,
    /// Lighting.
    shade: f64,
}

impl FrameStages {
    pub(super) fn median(records: &[FrameRecord], render: &[RenderStages]) -> FrameStages {
        let of = |stage: fn(&RenderStages) -> f64| median(render.iter().map(stage).collect());
        FrameStages {
            plan: median(records.iter().map(|r| r.plan_ms).collect()),
            prewarp: of(|r| r.prewarp_ms),
            draw: of(|r| r.draw_ms),
            geometry: of(|r| r.geometry_ms),
            shade: of(|r| r.shade_ms),
        }
    }
}

/// What `summary.json` holds.
#[derive(Serialize)]
pub(super) struct Summary {
    /// Frames rendered (path frames a slow frame skipped are not rendered).
    pub(super) frames: u32,
    /// Path frames flown.
    pub(super) path_frames: u32,
    pub(super) frame_ms_p50: f64,
    pub(super) frame_ms_p95: f64,
    pub(super) geometry_frame_ms_p50: f64,
    /// Frame by frame, over the frames timed as geometry that warped a texture, the
    /// all-geometry time over the same frame's as flown: the median. (`geometry_frame_ms_p50
    /// / frame_ms_p50` divides the medians of different frames: a path's frames are of
    /// different kinds, some showing many objects and some none.)
    pub(super) geometry_over_frame_paired_p50: f64,
    /// Where the frame time goes, each stage's median on its own.
    pub(super) frame_stages_ms_p50: FrameStages,
    pub(super) requests_now: u64,
    pub(super) requests_predicted: u64,
    pub(super) withdrawn: u64,
    /// Requests that ended without their texture: refused or broken off …
    pub(super) requests_failed: u64,
    /// … or unanswered within their deadline (and withdrawn) …
    pub(super) requests_timed_out: u64,
    /// … or still open when the flight ended; and predictions the saturated server
    /// refused.
    pub(super) requests_open_at_exit: usize,
    pub(super) requests_shed: u64,
    /// Final textures asked for by one placement of a mesh and given to others too.
    pub(super) textures_shared: u64,
    /// The mean factor the server's load put on the tolerance over the frames (1: the
    /// tolerance asked for throughout).
    pub(super) load_scale_mean: f64,
    /// The mean factor the link's round trips put on the tolerance (1: a link as short
    /// as the default tolerance is tuned for; see `LINK_TUNED_ROUND_TRIP`).
    pub(super) link_scale_mean: f64,
    /// Seconds the server could not serve (unreachable, or without a worker);
    /// `null` without a server.
    pub(super) degraded_s: Option<f64>,
    /// Request sent → final texture received by the client.
    pub(super) latency_ms_p50: f64,
    pub(super) latency_ms_p99: f64,
    /// The same of the requests needed now alone (a frame waits on them).
    pub(super) latency_now_ms_p99: f64,
    /// Of the predictions answered, the fraction whose texture came after the time it
    /// was predicted to be needed; `null` without any.
    pub(super) predictions_late_frac: f64,
    /// Final texture received → taken in by a frame.
    pub(super) pickup_ms_p50: f64,
    pub(super) pickup_ms_p99: f64,
    /// Seconds from a final texture's arrival to the last frame it was shown in.
    pub(super) texture_lifetime_s_p10: f64,
    pub(super) texture_lifetime_s_p50: f64,
    /// Final textures never shown, and of those, how many whose object was shown from
    /// its other textures after a frame took them in (`TextureLifetimes::superseded`).
    pub(super) textures_never_shown: u64,
    pub(super) textures_never_shown_superseded: u64,
    /// Needed textures already there or in flight, and the needs counted.
    pub(super) prediction_hits: u64,
    pub(super) needs: u64,
    pub(super) stale_frames: u64,
    /// Object-frames without a valid texture, by cause …
    pub(super) stale_causes: StaleCauses,
    /// … and those drawn as geometry instead, not stale.
    pub(super) stand_ins: u64,
    /// Impostors redrawn unchanged while Schaufler's sprite test held, and warped.
    pub(super) sprites: u64,
    pub(super) warps: u64,
    pub(super) partners: u64,
    /// Texels pre-warped per frame drawn, warps and partners together.
    pub(super) texels_warped_per_frame: f64,
    /// New textures received per full turn for each object orbited by the path.
    pub(super) regenerations_per_orbit: BTreeMap<String, f64>,
    /// Against the point-sampled reference (one ray through each pixel centre);
    /// `null` when no frame was compared (`--reference-every 0`).
    /// Over the pixels both show (any object)…
    pub(super) psnr_db_mean: Option<f64>,
    pub(super) psnr_db_min: Option<f64>,
    /// … over every pixel either shows (what a frame leaves empty or fills wrongly
    /// counts) …
    pub(super) psnr_whole_db_min: Option<f64>,
    /// … and the largest fraction of them only one of the two shows.
    pub(super) hole_frac_max: Option<f64>,
    /// Against the anti-aliased reference (3×3 rays per pixel) …
    pub(super) psnr_aa_db_mean: Option<f64>,
    pub(super) psnr_aa_db_min: Option<f64>,
    /// … which the same frames drawn all as exact geometry, one sample per pixel, do
    /// not reach either: the floor that detail finer than a pixel sets.
    pub(super) geometry_psnr_aa_db_min: Option<f64>,
    /// Per object that may be an impostor, the lowest PSNR of its own pixels against
    /// the anti-aliased reference — wherever either frame shows it, so silhouette
    /// errors count — over the compared frames where it covers at least
    /// [`MIN_JUDGED_OBJECT_PIXELS`](super::judge::MIN_JUDGED_OBJECT_PIXELS) pixels of
    /// the reference (the same frames for every figure by object below).
    pub(super) psnr_aa_db_min_by_object: BTreeMap<String, f64>,
    /// … and the floor for it: the object drawn as exact geometry, one sample per
    /// pixel, against the anti-aliased reference.
    pub(super) geometry_psnr_aa_db_min_by_object: BTreeMap<String, f64>,
    /// The median of the same, per object, for the impostor and for exact geometry.
    pub(super) psnr_aa_db_median_by_object: BTreeMap<String, f64>,
    pub(super) geometry_psnr_aa_db_median_by_object: BTreeMap<String, f64>,
    /// Per object, frame by frame, the impostor's figure minus exact geometry's: the
    /// worst frame's, and the median.
    pub(super) psnr_aa_gap_db_min_by_object: BTreeMap<String, f64>,
    pub(super) psnr_aa_gap_db_median_by_object: BTreeMap<String, f64>,
    /// Every how many frames drawn one was compared: `--reference-every`, doubled each
    /// time the frames kept for it passed their memory budget.
    pub(super) compared_every: u32,
    pub(super) rtt_ms: u64,
    pub(super) predict: bool,
    pub(super) tolerance: f32,
    /// Workers started; `None` with `--server` (whose own workers serve) or when no
    /// server could start (textures made in-process).
    pub(super) workers: Option<u32>,
    pub(super) source: String,
}

impl Summary {
    /// What went wrong with the requests, for the one line: nothing when nothing did.
    fn trouble(&self) -> String {
        let mut said = Vec::new();
        if self.requests_failed > 0 {
            said.push(format!("{} failed", self.requests_failed));
        }
        if self.requests_timed_out > 0 {
            said.push(format!("{} timed out", self.requests_timed_out));
        }
        if self.requests_open_at_exit > 0 {
            said.push(format!("{} open at exit", self.requests_open_at_exit));
        }
        if let Some(s) = self.degraded_s.filter(|&s| s > 0.0) {
            said.push(format!("server unable to serve for {s:.1} s"));
        }
        if said.is_empty() {
            String::new()
        } else {
            format!(" ({})", said.join(", "))
        }
    }

    /// The one line the demo prints: frames and their time against all geometry,
    /// requests and their latency, stale frames, image error; where the outputs went.
    pub(super) fn line(&self, (w, h): (u32, u32), out: &Path) -> String {
        format!(
            "{} frames ({}x{}) from {}: frame {:.1} ms p50 / {:.1} p95 (all geometry {:.1} ms); \
             {} requests now, {} predicted, latency {}{}; {} stale frames; PSNR {} -> {}",
            self.frames,
            w,
            h,
            self.source,
            self.frame_ms_p50,
            self.frame_ms_p95,
            self.geometry_frame_ms_p50,
            self.requests_now,
            self.requests_predicted,
            if self.latency_ms_p50.is_finite() {
                format!(
                    "{:.0} ms p50 / {:.0} p99",
                    self.latency_ms_p50, self.latency_ms_p99
                )
            } else {
                "not measured (no texture arrived during the flight)".to_string()
            },
            self.trouble(),
            self.stale_frames,
            match (self.psnr_db_mean, self.psnr_db_min) {
                (Some(mean), Some(min)) => format!("{mean:.1} dB mean, {min:.1} min"),
                _ => "not measured".to_string(),
            },
            out.display()
        )
    }
}
