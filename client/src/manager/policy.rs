//! Every tuning constant of the impostor manager, in one place, each with why it has
//! its value. The docs link here rather than restating numbers.
//!
//! Thresholds the renderer owns, because frames drawn without a manager (`relief
//! frame`, the reports) apply them too, are re-exported here so this page lists all the
//! manager obeys: which objects are drawn as geometry ([`CHEAP_TRIANGLES`],
//! [`NEAR_MARGIN`]) and how fine a texture must be for the screen
//! ([`MAX_TEXEL_PIXELS`], [`MIN_LEVEL_EDGE`]), and the critical-point error's regions
//! ([`CRITICAL_REGIONS`]).

use std::f32::consts::PI;
use std::time::Duration;

use glam::Vec3;
use relief_core::camera::Camera;
use relief_core::relief::{DepthBits, SourceCamera, SourceProjection};
use relief_core::scene::SceneObject;
use relief_render::validity::edges::EdgeError;
use relief_render::validity::schaufler::resolution_for;

pub use relief_render::geometry::{CHEAP_TRIANGLES, NEAR_MARGIN};
pub use relief_render::pyramid::{MAX_TEXEL_PIXELS, MIN_LEVEL_EDGE};
pub use relief_render::validity::critical::CRITICAL_REGIONS;

/// The manager's settings: `tolerance` and `predict` are `relief demo`'s flags; the
/// others, knobs for tests, default to their constants here.
#[derive(Debug, Clone)]
pub struct Config {
    /// Largest growth of the predicted gap (worst of [`CRITICAL_REGIONS`]² regions, eq.
    /// 5-5…5-7: neighbours' gaps over theirs at the texture's own eye, hidden surfaces
    /// whole), in screen pixels, before a texture counts as stale and a new one is
    /// needed: the impostor-lifetime knob.
    pub tolerance: f32,
    /// Ask for predicted textures (off: only when needed now).
    pub predict: bool,
    /// Round-trip estimate (seconds) before any request has been measured.
    pub initial_latency: f64,
    /// Textures kept per object.
    pub keep: usize,
    /// Triangles a frame may draw as geometry in the stead of objects without a valid
    /// texture ([`STAND_IN_TRIANGLES`]; 0: none, each such object counts as stale).
    pub stand_in_triangles: usize,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            tolerance: DEFAULT_TOLERANCE,
            predict: true,
            initial_latency: INITIAL_LATENCY_S,
            keep: TEXTURES_KEPT,
            stand_in_triangles: STAND_IN_TRIANGLES,
        }
    }
}

// ---- Settings' defaults -------------------------------------------------------------

/// `--tolerance`'s default, pixels of predicted gap growth: the demo's trade of frame
/// speed and regenerations against image error. Measured on the knot over 10 default
/// demo runs (944 paired frames), its median gap to exact geometry by growth: 0.7–1.0
/// dB above it under 6 px, 0.0 at 6–9, 1.8 below at 9–12 and 3.2 below at 12–18 —
/// where 24 let its textures live (its worst frames 5–12 dB below, the tube behind
/// showing through what the texture never saw).
pub const DEFAULT_TOLERANCE: f32 = 12.0;

/// The round trip planned for before any is measured: a loopback request of a 256²
/// texture takes 15–21 ms, so this errs towards asking early.
pub const INITIAL_LATENCY_S: f64 = 0.15;

/// Textures kept per object (those the last frame relied on, then the nearest the eye:
/// [`Manager::hold`](super::Manager)): enough for the pair around the eye
/// and those the path returns to, at a few MB each (about 25 MB at 1024², with its
/// pyramid).
pub const TEXTURES_KEPT: usize = 8;

// ---- Which texture is shown ---------------------------------------------------------

/// A texture's gap growth counts, against the tolerance, this many times over: 1, or
/// its [`EdgeError`] over [`EDGE_ERROR_REFERENCE`] where that is more. The growth is of
/// the widest gap; the image error a growth causes goes with how many edges open and
/// how much each shows.
pub fn growth_weight(edges: EdgeError) -> f32 {
    (edges.per_texel / EDGE_ERROR_REFERENCE).max(1.0)
}

/// The [`EdgeError`] up to which a texture's gap growth counts as it is
/// ([`growth_weight`]). Every solid here is under it (on 256² textures the knot's is
/// 0.0015–0.004, the rock's 0.0054, the bunny's 0.0004–0.002); the tree's (0.09–0.10)
/// is 2–3 times over, and its textures live that much less. Lower, the tree comes
/// nearer geometry but its textures cannot arrive in time: at 0.02 its median gap
/// in the demo was 3.7 dB (4.7–5.2 unweighted) with 4.4 % of frames stale at a 100 ms
/// round trip; at 0.004, 2.6 dB with 15 % stale at rtt 0 and 42 % at 100 ms; at this
/// value 4.0–4.7 dB with at most 0.7 % stale.
pub const EDGE_ERROR_REFERENCE: f32 = 0.04;

/// Beyond this turn around the object a texture is not used whatever the gap metric
/// says: the metric sees holes between neighbours, not the stretching of a view seen
/// from far off its axis.
pub const MAX_TURN: f32 = 60.0 * PI / 180.0;

/// … nor beyond this change of distance from the object (either way), for the same
/// reason. (At 1.6 the sphere's worst demo frames were its near pass, the eye 1.45–1.54×
/// as far as its texture's eye about the object's centre (this bound is taken about the
/// texture volume's), the outline ragged: 10 runs, rtt 0 and 100, scored −2.5 to −5.7 dB
/// against geometry, 2 of them within 3 dB; at 1.5, −2.4 to −3.0 in 9 of 10 (the tenth
/// −5.0, another frame), for about 6 % more requests.)
pub const MAX_DISTANCE_RATIO: f32 = 1.5;

/// Beyond this turn a texture of a solid drawn without a partner counts as stale (and
/// one for now is asked for) at the default tolerance: alone, it misses the side of the
/// object the eye has turned to see. (A curved rim's band, [`LONE_BAND`], says so
/// sooner on an object large on screen; this bounds the rest: sharp edges, and the
/// texels just inside a rim, grazed by the texture's rays, which a turned eye sees
/// stretched.) A small object's band stays narrow far round: with the limit at 30°, the
/// demo's sphere, 70 px across, was shown alone 16° from its first texture, its turned
/// rim ragged, 3.3–3.8 dB below geometry's worst in 8 runs of 9 (rtt 0 and 100; the
/// same frame from the same texture with a partner scored as geometry). At 15° (where
/// partners start, [`PARTNER_FROM`]) −0.2 to −1.5 in 6, as many requests, and the
/// sphere's orbit asks 13 textures where it asked 12 (at 12°, 16, with 9 stale frames in
/// the demo). It scales with the tolerance up to [`LONE_TURN_CAP`] (see `may_show`).
pub const LONE_MAX_TURN: f32 = 15.0 * PI / 180.0;

/// The farthest any texture is shown alone, whatever the tolerance, and how far a
/// texture of leaves or sheets
/// ([`EdgeCensus::is_sheets`](relief_core::mesh::EdgeCensus::is_sheets)) is at the
/// default one: it has no rim of grazed texels, and trees near the eye turn fast (at
/// 15° the forest at 1280×720 over a 100 ms round trip went stale in 16–20 % of its
/// frames in 2 runs, against 7–9 % at this, asking 900–920 predictions where it asked
/// 700–740). At 40°, the scanned bunny flown at a 100 ms round trip was shown 29° from
/// its only texture early in the flight, its turned side stepped, 3.10–3.16 dB below
/// geometry's worst frame in 4 runs of 5; at 30°, 1.05–1.08 in 3.
pub const LONE_TURN_CAP: f32 = 30.0 * PI / 180.0;

/// How far a solid's perspective texture ([`OWN_EYE_GROWTH`]) is shown alone at the
/// default tolerance: its rays graze the outline its own eye sees, nearer than the one
/// parallel rays graze, so a turn uncovers surface past its rim sooner than the rim's
/// band foresees. The scanned bunny, every texture in perspective (then at the sheets'
/// texel; every frame judged, 2–3 runs each): alone up to [`LONE_MAX_TURN`], its worst frame 5.1 dB below
/// geometry's worst (a texture 10° round, the far side of its body short of its
/// outline); up to 8°, 2.8–3.6 below; up to 6°, 2.8 in both runs. With the switch as
/// kept, up to 5°: 1.3–4.3 below (1 run of 4 over 3), 37–41 textures asked where 6°
/// asked 32–33. (Once an object has switched, its orthographic textures shown alone
/// no farther round either: at rtt 0 the bunny then showed a coarse preview instead,
/// 3.8 dB below geometry's worst in 3 runs of 3.)
pub const PERSPECTIVE_LONE_TURN: f32 = 6.0 * PI / 180.0;

/// The turn past which a texture of `object` in `projection` counts as stale drawn
/// alone at the default tolerance: [`LONE_TURN_CAP`] for leaves or sheets
/// ([`EdgeCensus::is_sheets`](relief_core::mesh::EdgeCensus::is_sheets), whichever way
/// its textures' rays go: near the eye they are asked orthographic),
/// [`PERSPECTIVE_LONE_TURN`] for a solid's perspective texture, else
/// [`LONE_MAX_TURN`].
pub fn lone_max_turn(object: &SceneObject, projection: SourceProjection) -> f32 {
    if object.edge_census().is_sheets() {
        LONE_TURN_CAP
    } else if projection == SourceProjection::Perspective {
        PERSPECTIVE_LONE_TURN
    } else {
        LONE_MAX_TURN
    }
}

/// A texture drawn without a partner counts as stale once the band past its rim it
/// cannot show ([`Rim::band`](relief_render::validity::rim::Rim::band)) is wider than
/// this, in pixels. Measured on the sphere (`the_band_past_the_rim_is_what_the_warp_leaves_empty`):
/// a predicted 0.9 px loses nothing, 3.5 px loses 1.4 px of outline on average and up to 3
/// in a row — the spikes the eye sees — so at 2 px about half a pixel is lost.
pub const LONE_BAND: f32 = 2.0;

/// A texture drawn without a partner counts as stale once more than this share of the
/// surface the eye sees face-on was turned away from or edge-on to its rays
/// ([`NormalCensus::unseen_share`](relief_core::normals::NormalCensus::unseen_share),
/// each part seen along the line from the eye to it): past a sharp edge a flat face
/// comes into view at once, and the texture shows a hole the rim's band does not
/// foresee. The scanned fandisk's side came into view as 7.1 % at 8.7° and 15.8 % at
/// 11.6° (the object 11 and 14.5 dB below geometry in those frames; seen along one
/// line, the census's first way), its fin's narrow side as 2.0 % at 4° and 3.5 % at 7°
/// (−7.3 dB at 4°; 1.1 % and 2.5 % along one line). At 3 %, the fandisk's flight at a
/// 100 ms round trip showed its sixth frame from a texture 4.3° round leaving 0.57 %
/// unseen, the fin's narrow side a pixel-wide strip missing from its outline: 5 dB
/// under the same frame's geometry, its worst frame 3.7–3.8 dB under geometry's worst (4
/// runs; 2.1–2.2 at rtt 0, 4 runs). At 0.5 % the texture is given a partner: 0.62–0.82
/// dB (4 runs at rtt 100), 0.81–0.91 at rtt 0 (2). What that costs: more textures shown
/// with partners or objects drawn as geometry meanwhile (the default scene at rtt 100:
/// 18–31 partners and 9–32 stand-ins a run, against 5–8 and 6–15), and the teapot's worst
/// frame 4.2 dB under geometry's in 1 run of 12 (a texture 13° round partnered by one
/// 8.7° round, past the tolerance; 2.0–2.65 in 12 of 12 at 3 %), the partner then a
/// level coarser — at the screen's level 1.95 dB (`Manager::partner`): see `targets.md`. A
/// smooth convex surface turns into view slowly, `(1 − cos φ)/2` on a sphere seen from
/// far (0.5 % at about 8°, short of [`LONE_MAX_TURN`]), and less round its outline from
/// near (0.1 % at 15° from 5 radii): the orbit's sphere gave 13 textures an orbit either
/// way. (A partner, from the far side of the eye, holds what turned into view: with
/// one, the rim's band and the turn bound the texture.)
pub const LONE_UNSEEN: f32 = 0.005;

/// With a partner filling the band past its rim, a texture counts as stale once that
/// band is wider than this, in pixels: the texels just inside the rim, grazed by the
/// texture's rays, stretch over as much again (the sphere shown 35–47° from its eye with
/// a partner, bands of 14–39 px, scored 11–17 dB below geometry).
pub const PARTNERED_BAND: f32 = 4.0;

/// A texture whose texels would cover more than this many pixels' angle is not shown:
/// while a finer texture is on its way the object stands in as geometry, or counts as
/// stale where it cannot (the frame is not valid); near an object where even the
/// largest texture is that coarse, geometry is drawn while the eye stays that near, and
/// the frame is valid.
pub const COARSEST_SHOWN: f32 = 2.0 * MAX_TEXEL_PIXELS;

/// A texture whose texels cover more than this many pixels' angle at the eye is
/// replaced by a finer one where one can be had: asked for while it is still shown (up
/// to [`COARSEST_SHOWN`]), and planned for where the eye is going. Textures magnified
/// past a pixel as the eye drew near were the default demo's worst frames (texels of
/// 1.2–1.5 px: the knot, the rock and the sphere 5–6 dB below exact geometry). A tenth
/// past the pixel: a texture asked for at a pixel's texel ([`MAX_TEXEL_PIXELS`]) is not
/// asked for again as soon as the eye steps nearer.
pub const REFINE_TEXEL: f32 = 1.1 * MAX_TEXEL_PIXELS;

/// A texture this many times over the tolerance is not shown: geometry is drawn until a
/// better one arrives (the frame still counts as stale).
pub const SHOWN_STALE: f32 = 2.0;

// ---- Partners: a second texture drawn behind the shown one ----------------------------

/// A partner is drawn once the eye is this far around the object from the shown
/// texture's eye (or the band past its rim is over [`LONE_BAND`]): nearer, what the
/// texture cannot show is a sliver a pixel or two wide, not worth a second warp.
pub const PARTNER_FROM: f32 = 15.0 * PI / 180.0;

/// A partner is at most this far around the object from the eye, as a shown texture:
/// farther, it fills the band past the shown texture's rim with texels seen stretched,
/// and it keeps that texture counted as covering the eye (the partnered band) where a
/// nearer one is due. At twice this, the sphere turned 16–22° from its texture with
/// partners 73–80° off scored 3–5 dB under geometry, and its median over the demo's
/// first 150 frames 1.0–1.7 dB under (partners then a level coarser); at this turn, new
/// textures come sooner (the orbit-sphere scene asks 20 an orbit, not 17).
pub const PARTNER_MAX_TURN: f32 = MAX_TURN;

/// How far behind the shown texture a partner is drawn, as a fraction of the object's
/// bounding radius: more than two textures of one surface disagree on its depth (depth
/// quanta, reconstruction), so the partner shows only where the shown one has nothing.
pub const PARTNER_BEHIND: f32 = 0.05;

// ---- What is asked for, and when ----------------------------------------------------

/// The texture edges asked for: half-octave steps from 32 to 1024 (32·√2^k, rounded to
/// multiples of 8), so a texture has at most 2.1× the texels the screen can show (with
/// power-of-two edges, up to 4×), each warped every frame. A solid's textures stop at
/// [`SOLID_MAX_EDGE`], a sheet's at [`SHEET_MAX_EDGE`] ([`largest_edge`]).
pub const TEXTURE_LADDER: [u32; 11] = [32, 48, 64, 88, 128, 184, 256, 360, 512, 720, 1024];

/// The largest texture edge asked for a solid: beyond it a texture costs more to warp
/// each frame than the object's few screen-filling frames gain. At 512, the demo's
/// near passes showed the sphere and the rock at texels of 1.4–1.6 pixels, 4–7 dB below
/// exact geometry; at 720 the rock's texel stayed under a pixel, but the knot, passing
/// the eye, was shown at 1.04-pixel texels, its silhouette stepped and short of the
/// rim, its worst frame 4.2–6.7 dB below geometry's in 4 runs of 5. At 1024 an object
/// whose texture would need more than 720 a side is drawn as geometry where its
/// triangles cost less ([`cheaper_as_geometry`]: the knot there), and the rock gets the
/// texels it needs: one 1024² pre-warp costs about four 512² ones (2.1 ms on one
/// core), on the few frames of its near pass (in the demo, one run of four asked for
/// one; the frame's median speed was unchanged, 2.8–3.1× geometry's against 2.4–3.3×).
pub const SOLID_MAX_EDGE: u32 = 1024;

/// The largest texture edge asked for a texture of `object` in `projection`:
/// [`SHEET_MAX_EDGE`] for the perspective textures of leaves and sheets
/// ([`projection_for`]), else [`SOLID_MAX_EDGE`].
pub fn largest_edge(object: &SceneObject, projection: SourceProjection) -> u32 {
    match sheet_texels(object, projection) {
        true => SHEET_MAX_EDGE,
        false => SOLID_MAX_EDGE,
    }
}

/// Whether a texture of `object` in `projection` is one of leaves or sheets, seen as
/// they are from the eye itself: asked for and shown at [`SHEET_TEXEL_PIXELS`], up to
/// [`SHEET_MAX_EDGE`]. (A solid's perspective texture keeps a solid's texel and edges:
/// at 720 a side, the knot near the eye showed texels of 1.5 pixels.)
fn sheet_texels(object: &SceneObject, projection: SourceProjection) -> bool {
    projection == SourceProjection::Perspective && object.edge_census().is_sheets()
}

/// Depth precision asked for: 16 bits, not the thesis' 8. Near an object, where the
/// pre-warp folds its rim, many texels land near its outline, and with 8 bits each
/// one's rounding moves it by up to a third of a pixel: the outline takes the
/// outermost of them and swells (a sphere at 2.4 radii: 0.40 pixels wider than its
/// reference, 0.06 with 16 bits), losing 3 dB over its lower half.
pub const REQUESTED_DEPTH_BITS: DepthBits = DepthBits::Sixteen;

/// The projection a texture of `object` is asked in for `eye`. From the eye itself
/// for open surfaces (leaves, sheets — [`SHEET_RIM_SHARE`](relief_core::mesh::SHEET_RIM_SHARE)): it holds the leaves that
/// parallel rays graze edge-on (the tree at its texture's own eye: 24–25 dB against
/// exact geometry's 26–29, where an orthographic texture scores 12–16; from an eye
/// moved by 3–10 % of its distance, 15–20 dB against 11.5–16). Orthographic for closed
/// surfaces: from the eye itself, a texture shown to an eye that moved misses the rim
/// of the outline that eye sees (the knot: 3–5× the holes, 1–4 dB below an
/// orthographic texture), where parallel rays see the whole outline. (A centre set
/// back to twice the eye's distance did better than either on the knot alone, but in
/// the demo left the knot 1 dB and the rock 0.5 dB further below geometry.)
/// Orthographic too where the eye is too near the bounds for a perspective texture
/// ([`MAX_PERSPECTIVE_TANGENT`](relief_core::relief::MAX_PERSPECTIVE_TANGENT)), and for
/// a solid with a few holes, whose rim is under [`SHEET_RIM_SHARE`](relief_core::mesh::SHEET_RIM_SHARE) of its edges.
/// But from the eye itself, when `in_perspective`, for a solid whose orthographic
/// textures fall short of what their own eye sees ([`OWN_EYE_GROWTH`]).
///
/// `eye`, here and in the other functions of an object and a camera below, is in the
/// object's frame ([`SceneObject::local_camera`]).
pub fn projection_for(object: &SceneObject, eye: Vec3, in_perspective: bool) -> SourceProjection {
    if (in_perspective || object.edge_census().is_sheets())
        && SourceCamera::facing(eye, &object.local_bounds, 1, 1, SourceProjection::Perspective).is_ok()
    {
        SourceProjection::Perspective
    } else {
        SourceProjection::Orthographic
    }
}

/// A solid's orthographic texture falls short of what its own eye sees when it opens
/// gaps this wide (screen pixels, weighted as against the tolerance) seen from that
/// eye: half the default tolerance spent before the eye has moved. The scanned bunny's
/// fell short from the front and from behind (by 6.5–13.8 px), and its worst frames
/// were theirs: 3–7 dB below geometry's same frame, at turns of 0.2–5.6°, the ears'
/// undersides missing. The default scene's sphere never opens any; its knot one or two
/// of its 39–43 textures a run (8.1–9.6 px), its rock up to two of 26–30 (8.3–19.6 px;
/// others 4.3–5.8: at 4 px, 2 of them in 3 textures switched it in 3 runs of 4, its
/// median 0.5–0.8 dB lower, still 2.2–2.5 above geometry's). See
/// `manager/perspective.rs`.
pub const OWN_EYE_GROWTH: f32 = 0.5 * DEFAULT_TOLERANCE;

/// An object's textures are asked in perspective once this many of its last
/// [`SHORT_WINDOW`] final orthographic ones fell short ([`OWN_EYE_GROWTH`]): the
/// object's shape, not one view's — unless that view cannot show its texture and asks
/// for it again (each time received counts: `manager/perspective.rs`). The bunny's fall
/// short several in a row, the knot's and the rock's one at a time. (Switched by its
/// one, the knot's worst frame fell 4.0 and 7.3 dB below geometry's worst in 2 runs of
/// 3, on its near pass.)
pub const SHORT_NEEDED: u32 = 2;

/// How many of an object's latest final orthographic textures [`SHORT_NEEDED`] counts
/// among.
pub const SHORT_WINDOW: u32 = 3;

/// The texel, in pixels' angles, asked for and shown where the texture stays within
/// [`FINE_TEXEL_MAX_EDGE`]: a texel of a pixel
/// ([`MAX_TEXEL_PIXELS`]) resamples the
/// shading (the sphere at its own eye: 31.6 dB with 121² texels, 38.0 with 242²,
/// geometry 37.2). In the demo (3 runs each) the sphere's median gap to geometry was
/// 3.0–3.6 dB at 0.7, 3.2–4.6 at 0.5 (5 runs) and 5.2–6.4 at one pixel; 0.7 warps
/// 15 % more texels a frame than one pixel, 0.5 22 %. (Measured, as the figures
/// of [`FINE_TEXEL_MAX_EDGE`], with the pixel's angle at the view's centre, before the
/// resolution test took it where the object shows, `Camera::pixel_angle_towards`.)
pub const FINE_TEXEL_PIXELS: f32 = 0.7;

/// The largest texture edge [`FINE_TEXEL_PIXELS`] may ask for: a pre-warp costs per
/// texel, and the objects that fill the frame, whose textures are larger, keep the
/// coarser texel (at half a pixel for every object the frame was 2.9–3.2× faster
/// than geometry, against 5.6–5.9× at one). Measured in the demo, median gap to
/// geometry of the knot, rock and sphere, and frame speed: at 256, knot 0.8–1.9 dB
/// (9 runs), 4.8–6.2×; at 360, every one within 1 dB (5 runs), 4.3–4.8×; at 512,
/// within 0.6 dB (2 runs), 4.3–4.4×. Fidelity first: the speed waits on the pre-warp's.
pub const FINE_TEXEL_MAX_EDGE: u32 = 360;

/// The texel, in pixels' angles, a texture of leaves or sheets (perspective,
/// [`projection_for`]) is asked for and shown at, up to [`SHEET_MAX_EDGE`]. Leaves are
/// nearly all edge, and every edge a warp resamples moves by up to half a texel: the
/// tree at its texture's eye, in a 256² frame, scores 23.2 dB with a 256² texture,
/// 23.9 with 360², 24.5 with 512², against exact geometry's 25.0. In the demo (whole
/// path, 2 runs each) its median gap to geometry was 2.9–3.3 dB at 0.6 (up to 720²)
/// against 4.1–4.3 at [`FINE_TEXEL_PIXELS`] (up to 360², then a pixel); 0.5 (up to
/// 720² or 1024²) gained no more over the first 150 frames (2.1–2.5 dB, against
/// 2.2–2.3 at 0.6) and warped 1.3–1.5× the texels. The frame was 3.7–4.1× faster than
/// geometry, against 4.3–4.7×. (Since [`cheaper_as_geometry`], the tree itself is drawn
/// as geometry wherever its texture would pass 351 a side: the larger edges serve
/// leaves of more triangles, and trees afar.)
pub const SHEET_TEXEL_PIXELS: f32 = 0.6;

/// The largest texture edge asked for leaves or sheets ([`SHEET_TEXEL_PIXELS`]).
pub const SHEET_MAX_EDGE: u32 = 720;

// ---- Geometry where it costs no more, and in the stead of stale textures ------------

/// Nanoseconds this client's rasterizer takes a triangle of leaves, shading included:
/// drawn as geometry in the demo, the default scene's tree (9,228 triangles) added
/// 1.2–1.6 ms to the frame's geometry stage (5 runs). (Smaller triangles cost less:
/// the rock's million take 28–32 ms.)
pub const GEOMETRY_NS_PER_TRIANGLE: f32 = 160.0;

/// Nanoseconds a texel of a texture costs a frame, pre-warp and texture mapping: the
/// same runs' pre-warp and mapping stages fell by 1.9–2.0 ms with the tree's 157 k
/// texels a frame gone (a texture of leaves, mostly empty texels; a solid's cost more:
/// `relief bench warp`'s 256² pre-warp alone is 17 ns a texel).
pub const WARP_NS_PER_TEXEL: f32 = 12.0;

/// Whether `object` costs no more drawn as geometry than as an impostor whose texture
/// has `edge` texels a side (then it is drawn as geometry, which is exact). With the
/// costs above, the default scene's tree is drawn as geometry once its texture would
/// pass 351 texels a side, the sphere (20 k triangles) past 522 (its textures of 720),
/// the knot (46 k) past 784 (only at a solid's largest, 1024), and the rock (a
/// million) never. In the demo (whole
/// path, rtt 0 and 100, against the same before) the tree then matched geometry where
/// its impostor was 2.9–3.3 dB below, the frame took 6.45–6.64 ms where it took
/// 6.63–6.73, and 84–119 textures were asked for where 125–143 were.
pub fn cheaper_as_geometry(object: &SceneObject, edge: u32) -> bool {
    let geometry = object.mesh.triangle_count() as f32 * GEOMETRY_NS_PER_TRIANGLE;
    geometry <= (edge as f32).powi(2) * WARP_NS_PER_TEXEL
}

/// An object without a valid texture — none held yet, or none within tolerance of the
/// eye — is drawn as geometry, exact and so not stale, nearest first, each that still
/// fits within this many triangles a frame: the frame is slower, not wrong, until its
/// texture comes. (Past it, an object shows its texture beyond the tolerance where one
/// can be shown, else is drawn as geometry all the same, and counts as stale.) A
/// million small triangles (the rock) take 13 ms on two cores at 640×360 and 27 ms at
/// 1280×720, the default tree's 9,228 about 1.3 ms (`relief bench raster`): at most
/// about 26 and 55 ms of stand-ins a frame. The forest's low flight at 1280×720, 100 ms
/// round trip, 3 runs each: 0, 2 and 1 stale frames of 272–283 (≤ 0.7 %), against
/// 13–16 of 266–287 (4.6–5.7 %) when only objects costing at most twice their impostor
/// stood in; 14–22 object-frames a run stood in, the median frame 52.4–56.6 ms
/// against 52.3–60.6 and the 95th percentile 116–122 against 114–119. Its stale frames
/// before had one to three objects without a texture each, rocks (a million triangles
/// each) among them.
pub const STAND_IN_TRIANGLES: usize = 2_000_000;

/// The texel, in pixels' angles, a texture of `object` is asked for and shown at from
/// `camera` (`in_perspective` as [`projection_for`] takes it): [`SHEET_TEXEL_PIXELS`]
/// for the perspective textures of leaves and sheets; for the others
/// [`FINE_TEXEL_PIXELS`] while that keeps within [`FINE_TEXEL_MAX_EDGE`], else
/// [`MAX_TEXEL_PIXELS`].
pub fn texel_pixels(object: &SceneObject, camera: &Camera, in_perspective: bool) -> f32 {
    let projection = projection_for(object, camera.eye_f32(), in_perspective);
    if sheet_texels(object, projection) {
        return SHEET_TEXEL_PIXELS;
    }
    match fine_edge(object, camera, projection) {
        Some(_) => FINE_TEXEL_PIXELS,
        None => MAX_TEXEL_PIXELS,
    }
}

/// What a texture of `object` is asked for in from `camera`: its projection
/// ([`projection_for`], with `in_perspective`) and the fewest texels per edge at its
/// texel ([`texel_pixels`], eq. 5-1: [`resolution_for`]); no edge when no texture faces
/// the eye.
pub fn asked_for(
    object: &SceneObject,
    camera: &Camera,
    in_perspective: bool,
) -> (SourceProjection, Option<u32>) {
    let eye = camera.eye_f32();
    let projection = projection_for(object, eye, in_perspective);
    let edge = match sheet_texels(object, projection) {
        true => resolution_for(&object.local_bounds, eye, projection, camera, SHEET_TEXEL_PIXELS),
        false => fine_edge(object, camera, projection)
            .or_else(|| resolution_for(&object.local_bounds, eye, projection, camera, MAX_TEXEL_PIXELS)),
    };
    (projection, edge)
}

/// The edge at [`FINE_TEXEL_PIXELS`], if it keeps within [`FINE_TEXEL_MAX_EDGE`].
fn fine_edge(object: &SceneObject, camera: &Camera, projection: SourceProjection) -> Option<u32> {
    resolution_for(
        &object.local_bounds,
        camera.eye_f32(),
        projection,
        camera,
        FINE_TEXEL_PIXELS,
    )
    .filter(|&edge| edge <= FINE_TEXEL_MAX_EDGE)
}

/// Predicted textures are asked for once the eye's future leaves this fraction of the
/// tolerance, so that a late answer or a wrong guess still finds the texture in use
/// within the tolerance itself.
pub const PLANNING_MARGIN: f32 = 0.75;

/// How far past the predicted eye predicted textures are made: as far as a held
/// texture, seen from that far behind its own eye, keeps its gaps' growth within this
/// share of the tolerance (and its rim's band and turn within the planning margin:
/// `Manager::lead_angle`; with no texture held yet, this share of the valid angle). A
/// texture then serves that turn twice, behind its eye and ahead. Once the eye has
/// passed the shown texture's, the next one is its partner; none is asked for to be a
/// partner alone. (Keeping one texture asked for two valid angles past the eye's
/// future, as a partner, cost a third more requests and bought no fidelity measured.
/// Without it against with it: forest, rtt 100, 5 runs against 7, 1,385–1,628
/// predictions against 1,819–2,276, stale frames 15–24 % against 14–25 %, objects
/// within 1 dB of geometry 89–106 against 84–92; 64 clients, four alternating pairs,
/// p99 latency 0.37–1.24 s against 1.64–2.21 s.) At the
/// planning margin's share (0.75) the bunny at rtt 100 went stale in 3 frames of 120 in
/// each of 3 runs, seen 8–12° from textures whose gaps grew 13–14 px; at 0.5, in none.
pub const LEAD: f32 = 0.5;

/// The predicted path past the eye's future that [`LEAD`] is measured along: this many
/// eyes, evenly spaced over the time the eye, turning as it has, takes to turn the lead
/// (at least the horizon again, the whole path within [`MAX_HORIZON_S`]; if the eye
/// slows, the lead ends at the last).
pub const LEAD_PATH_STEPS: usize = 4;

/// The lead stops where the path's distance from the object leaves this fraction of the
/// future eye's: a texture first seen from farther or nearer than its own eye as well as
/// turned from it shows a ragged outline (the sphere, 10° round with its eye 1.39× as far
/// as the texture's, 4–5 dB below geometry where 0.2 let the lead go), and a request
/// made past [`PENDING_DISTANCE_SLACK`] would not count as covering the future.
pub const LEAD_DISTANCE_SLACK: f32 = 0.1;

/// A lead (radians) below this is none: the texture is made for the future eye itself.
pub const MIN_LEAD: f32 = 1e-4;

/// A request already out serves an eye within this fraction of the object's valid
/// angle of its own eye (a fifth kept for the eye's further motion) …
pub const PENDING_REACH: f32 = 0.8;

/// … and within this fraction of its distance from the object.
pub const PENDING_DISTANCE_SLACK: f32 = 0.2;

/// A texture made for another eye within this fraction of the object's valid angle of
/// the one asked for serves a request: one the server holds or is making for another
/// client, or another placement. Such a texture still covers its lead twice over, less
/// `SERVE_REACH` of a valid angle, and clients flying through one scene
/// share their textures rather than each waiting for its own (see
/// docs/load-test.md). At 0.5, 64 clients of `relief load` stalled 17–20 % of their
/// frames where at 0.25 they stall 23–26 %, but a lone client over a 250 ms round
/// trip went stale in 2.5–3.2 % of its frames where at 0.25 it did 1.1–1.4 % (and
/// 0.9–1.4 % sharing nothing; both before predictions led along the path, since
/// which it does 0–0.5 %).
pub const SERVE_REACH: f32 = 0.25;

/// Predictions farther than this many valid angles from both the eye and its future are
/// withdrawn: the motion has left them behind.
pub const WITHDRAW_REACH: f32 = 2.0;

/// The valid angle assumed for an object before any of its textures has been probed:
/// small, so the first predictions come early.
pub const DEFAULT_VALID_ANGLE: f32 = 4.0 * PI / 180.0;

/// A texture's valid angle is probed from this turn, doubling, …
pub const PROBE_START: f32 = 0.5 * PI / 180.0;

/// … while below this: a bound on the probe, since past [`MAX_TURN`] no texture is
/// within the tolerance anyway.
pub const PROBE_LIMIT: f32 = 0.5 * PI;

/// … then refined this many halvings between the last turn within the tolerance and
/// the first beyond: to 1/16 of the step, finer than the eye moves in a frame.
pub const PROBE_REFINEMENTS: u32 = 4;

// ---- The frame's own work ------------------------------------------------------------

/// The fewest objects one task of a frame's assessment takes (grading each held
/// texture at the eye and where it is going): fewer than twice as many are assessed
/// on the calling thread, where waking the pool's threads (about 0.1 ms) costs more
/// than it saves (measured in `docs/targets.md`, "Many impostors").
pub const ASSESSMENTS_PER_TASK: usize = 16;

/// The most pre-warps a run keeps to time again ([`Manager::sample_warps`](super::Manager::sample_warps)),
/// and the most `relief bench replay` reads: enough for every kind of object a flight
/// warps, a second or two of replay each.
pub const MAX_WARP_SAMPLES: usize = 256;

/// The texels of the textures the kept pre-warps hold past the cache's eviction (each
/// texture counted once, at its full size): a texture made ready, its pyramid,
/// connectivity and critical points, takes about 24 bytes a texel, so about 400 MB.
pub const MAX_WARP_SAMPLE_TEXELS: usize = 16 << 20;

// ---- The server's load ------------------------------------------------------------------

/// A server foreseeing that a new job would wait longer than this behind the others
/// (its `queue_wait_ms`), or refusing a prediction, is saturated: textures asked for
/// now come late, so the client lets the ones it holds live longer — its tolerance
/// times [`LOAD_STEP_UP`] at each of the server's reports (every
/// [`HEALTH_POLL`](crate::link::HEALTH_POLL)) — and asks for fewer. (Unloaded, a job
/// waits behind none: 0.)
pub const LOAD_HIGH_WAIT: Duration = Duration::from_millis(250);

/// … and below this it has room again: the factor falls back by [`LOAD_STEP_DOWN`] at
/// each report, to 1.
pub const LOAD_LOW_WAIT: Duration = Duration::from_millis(100);

/// The factor's step up per report: from 1 to [`MAX_LOAD_SCALE`] in about 3 s.
pub const LOAD_STEP_UP: f32 = 1.5;

/// The factor's step down per report: from [`MAX_LOAD_SCALE`] to 1 in about 35 s. Every
/// client hears the same server: stepping down as fast as up, 64 clients brought their
/// tolerances from 8 to 1.6 times the user's within 2 s of the queue's emptying, all at
/// once, and their textures went stale together (up to 18.1 % of a 20 s flight's frames
/// stalled, nearly all in the 6 s the factor took to climb back). At 1.1 (8 to 1 in
/// 11 s) they still went stale together as the factor reached 1, a few seconds into
/// the flight: the round trips rose to 23–1,022 ms and 2 of 6 runs stalled 2.8 and 13.3
/// %; at this step, 11–37 ms and 0.1 % in all 6, for 10–20 % fewer requests and client
/// 0's frames 0.3 dB lower (37.4–37.8 dB against 37.8–38.7), alternating runs. (Not
/// the episodes that follow forest runs: see docs/load-test.md.)
pub const LOAD_STEP_DOWN: f32 = 1.03;

/// The longest round trip the default tolerance is tuned for: the fidelity figures
/// were measured at 0 and 100 ms (this leaves 100 ms links' looks room for jitter).
/// Over a link whose looks' shortest round trip is longer, the tolerance grows in
/// proportion (see the manager's `link_scale` module).
/// At 250 ms, 5.0–8.0 % of the default demo's frames went stale at the default
/// tolerance, 3.7 % at 4/3 of it and 0.7 % at twice it; with the factor this gives
/// there (2.0), 0.45–0.68 % (3 runs).
pub const LINK_TUNED_ROUND_TRIP: Duration = Duration::from_millis(125);

/// The link's shortest round trip is taken over its looks in the last period of this
/// length or two: long enough to hold through a burst of load (a busy server answers
/// its looks late); short enough that a link that shortens for good is not held to its
/// old lives for long.
pub const ROUND_TRIP_FLOOR_PERIOD: Duration = Duration::from_secs(10);

/// The most the server's load and a long link together may multiply the tolerance by
/// (the load's factor stops where the two reach it): textures live at most this much
/// longer (in gap growth) than the user asked; past it, frames go stale.
pub const MAX_LOAD_SCALE: f32 = 8.0;

/// After a prediction of an object is refused by a server that reports itself
/// saturated, none of it is asked for this long (one load report): asked again at
/// once, it was refused again every frame, and at 64 clients the request rate doubled.
/// (A refusal in a passing burst, the server not reporting saturation, is asked again
/// at once: quiet then, one client at a 250 ms round trip went stale 2–3× as often.)
pub const SHED_QUIET: Duration = Duration::from_millis(500);

// ---- Round trips ----------------------------------------------------------------------

/// Round trips remembered, overall and per object.
pub const LATENCY_WINDOW: usize = 16;

/// Round trips of its own an object needs before it plans for them: a heavy object
/// takes longer to trace than the rest.
pub const OWN_LATENCIES: usize = 4;

/// The percentile of the remembered round trips planned for: they vary several-fold
/// with the workers' queue, and planning for a typical one stalls every slower one.
pub const LATENCY_PERCENTILE: f64 = 0.9;

/// How far past the planned round trip predictions look: at `--rtt-ms 100` fewer frames
/// went stale than with ×1 or ×1.5.
pub const HORIZON_SPARE: f64 = 1.25;

/// … and this much more, seconds: arrivals later than the [`LATENCY_PERCENTILE`] of the
/// recent ones were most of a flight's stale frames.
pub const HORIZON_MARGIN_S: f64 = 0.05;

/// How far (radians) the view may turn, any way, by the time a predicted texture
/// comes: an object the view would not show from the predicted eye, turned as now or
/// by up to this, gets no predicted texture, and what was asked for it is withdrawn —
/// unless the view is turning faster than this allows for, and as it will then look,
/// turned on at its rate, it shows the object (`Manager::prediction`: at a corner of
/// the default demo's path the rock came into view at rtt 100 with a texture made
/// 28–31° round, 8–11 dB below geometry; with the turn foreseen, 2.6–3.7 dB above).
/// (Predicted for wherever it lay, objects behind the eye and far off to its sides
/// were most of the forest's requests: with this, two runs at a 100 ms round trip
/// asked for 2,199–2,203 textures where 4,548–5,093 were, and 1,046–1,184 were never
/// shown where 3,328–3,365 were.)
pub const PREDICTED_VIEW_MARGIN: f32 = 30.0 * PI / 180.0;

/// How many times, evenly spaced back from the horizon to a typical round trip
/// ([`GLIMPSE_LATENCY_PERCENTILE`]), an object in view now but not shown at the horizon
/// is looked for at, to plan for its last glimpse (see `Manager::prediction`): at a
/// steady 100 ms round trip the spacing is a frame or two, about what a frame's own
/// planning moves on by; where the round trips spread (a lossy link: median 0.6 s,
/// p90 1 s) it is five, and the next frame looks between.
pub const HORIZON_FALLBACK_STEPS: usize = 4;

/// The percentile of the recent round trips from which on an object's last glimpse
/// is looked for (see [`HORIZON_FALLBACK_STEPS`]): a typical answer can still come in
/// time for it. (From the planned round trip on, [`LATENCY_PERCENTILE`], one slow
/// answer of the rock's over a lossy link raised it from 0.6 to 0.97 s as the eye
/// neared the rock, and the eye's sweep past it, 0.5–1 s ahead, was never planned
/// for: 20 frames stale.)
pub const GLIMPSE_LATENCY_PERCENTILE: f64 = 0.5;

/// The farthest ahead predictions look, seconds: the predictor's fit of the recent eyes
/// means little further out (but on a steady orbit).
pub const MAX_HORIZON_S: f64 = 3.0;

/// How often [`Manager::warm_up`](super::Manager::warm_up) looks for the first
/// textures.
pub const WARM_UP_POLL: Duration = Duration::from_millis(5);

#[cfg(test)]
mod tests {
    use super::*;
    use relief_core::scene::Scene;

    /// Perspective textures for leaves and sheets only: the tree's, not a solid's, nor
    /// a solid's with a hole (open, but nearly all its edges paired).
    #[test]
    fn perspective_textures_go_to_sheets_only() {
        use relief_core::generators::Generator;
        use relief_core::scene::SceneObject;
        let object = |generator: Generator, holed: bool| {
            let mut mesh = generator.build();
            if holed {
                mesh.triangles.pop();
            }
            SceneObject::new("object", mesh, glam::DVec3::ZERO, Default::default())
        };
        let tree = object(
            Generator::Tree {
                seed: 3,
                depth: 3,
                leaves: 4,
            },
            false,
        );
        let sphere = object(Generator::Sphere { subdivisions: 3 }, false);
        let holed = object(Generator::Sphere { subdivisions: 3 }, true);
        let far = |o: &SceneObject| {
            o.local_bounds.center() + Vec3::new(0.3, 0.2, 1.0) * 4.0 * o.local_bounds.extent().length()
        };
        assert!(!holed.is_closed());
        let (orthographic, perspective) = (SourceProjection::Orthographic, SourceProjection::Perspective);
        assert_eq!(projection_for(&tree, far(&tree), false), perspective);
        assert_eq!(projection_for(&sphere, far(&sphere), false), orthographic);
        assert_eq!(projection_for(&holed, far(&holed), false), orthographic);
        // Asked so, a solid's textures are in perspective too.
        assert_eq!(projection_for(&sphere, far(&sphere), true), perspective);
    }

    /// A texture's gap growth counts more where its surfaces part often and differ
    /// much: the tree's (its leaves) more than once over; the knot's (a few crossings
    /// of its tube) and the sphere's (none) as it is. (Fails with the weight left at 1,
    /// or the reference under the knot's edges.)
    #[test]
    fn growth_counts_more_on_textures_full_of_edges() {
        use relief_render::impostor::Impostor;
        use relief_trace::bake;
        use relief_trace::tracer::ObjectTracer;
        let scene = Scene::load("default").expect("default scene");
        let weight = |name: &str| {
            let object = scene.object(name).expect("object");
            let eye = object.local_bounds.center()
                + Vec3::new(0.3, 0.4, 1.0) * 3.0 * object.local_bounds.extent().length();
            let texture = bake(
                &ObjectTracer::new(object),
                eye,
                256,
                REQUESTED_DEPTH_BITS,
                projection_for(object, eye, false),
            )
            .expect("bake");
            growth_weight(EdgeError::of(&Impostor::new(texture)))
        };
        let (tree, knot, sphere) = (weight("tree"), weight("knot"), weight("sphere"));
        assert!(tree > 1.5, "tree {tree}");
        assert_eq!((knot, sphere), (1.0, 1.0));
    }

    /// Leaves are drawn as geometry where their texture would be large, the sphere from
    /// its 720² textures, the knot only at a solid's largest (1024); the rock never is.
    #[test]
    fn geometry_where_it_costs_no_more() {
        let scene = Scene::load("default").expect("default scene");
        let object = |name| scene.object(name).expect("object");
        let (tree, knot, sphere, rock) = (object("tree"), object("knot"), object("sphere"), object("rock"));
        assert!(cheaper_as_geometry(tree, SHEET_MAX_EDGE) && cheaper_as_geometry(tree, 360));
        assert!(!cheaper_as_geometry(tree, 256));
        assert!(!cheaper_as_geometry(rock, SOLID_MAX_EDGE));
        assert!(cheaper_as_geometry(sphere, 720) && !cheaper_as_geometry(sphere, 512));
        assert!(cheaper_as_geometry(knot, SOLID_MAX_EDGE) && !cheaper_as_geometry(knot, 720));
    }

    /// Small textures of solids get the fine texel, those the frame is full of the
    /// pixel-sized one; leaves get the sheet's texel, up to the sheet's largest edge.
    #[test]
    fn fine_texels_go_to_the_textures_that_stay_small() {
        let scene = Scene::load("default").expect("default scene");
        let object = |name| scene.object(name).expect("object");
        let (sphere, tree) = (object("sphere"), object("tree"));
        let look = |eye: Vec3, at: Vec3| Camera::look_at(eye, at, Vec3::Y, 60.0, 640, 360).expect("camera");
        let far = look(
            sphere.local_bounds.center() + Vec3::new(0.0, 1.0, 12.0),
            sphere.local_bounds.center(),
        );
        assert_eq!(texel_pixels(sphere, &far, false), FINE_TEXEL_PIXELS);
        assert_eq!(texel_pixels(sphere, &far, true), FINE_TEXEL_PIXELS);
        let near = look(
            tree.local_bounds.center() + Vec3::new(0.0, 1.0, 5.0),
            tree.local_bounds.center(),
        );
        assert_eq!(texel_pixels(tree, &near, false), SHEET_TEXEL_PIXELS);
        let (projection, edge) = asked_for(tree, &near, false);
        assert_eq!(projection, SourceProjection::Perspective);
        assert!(edge.is_some_and(|e| e > SHEET_MAX_EDGE), "{edge:?}");
        assert_eq!(largest_edge(tree, projection), SHEET_MAX_EDGE);
        assert_eq!(largest_edge(sphere, projection), SOLID_MAX_EDGE);
        let near_sphere = look(
            sphere.local_bounds.center() + Vec3::new(0.0, 0.0, 2.0),
            sphere.local_bounds.center(),
        );
        assert_eq!(
            texel_pixels(sphere, &near_sphere, false),
            relief_render::pyramid::MAX_TEXEL_PIXELS
        );
        // Inside the bounds no texture is asked for: the coarser texel, no panic.
        let inside = look(sphere.local_bounds.center(), Vec3::new(10.0, 0.0, 0.0));
        assert_eq!(
            texel_pixels(sphere, &inside, false),
            relief_render::pyramid::MAX_TEXEL_PIXELS
        );
    }
}
