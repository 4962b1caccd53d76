//! The impostor manager: per object and frame, decide geometry / warp / regenerate,
//! keep a cache of relief textures, and ask for the textures the eye will need —
//! predicted ahead of need, early enough to cover the measured round trip — without
//! ever waiting for the network: requests go out on a channel, textures come back on
//! another, and each frame takes whatever has arrived.

use std::collections::HashMap;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender};

use relief_core::camera::Camera;
use relief_core::frame::Frame;
use relief_core::relief::{DepthBits, ReliefTexture};
use relief_core::scene::{Scene, SceneObject};

use crate::composite::{GeometryReason, MIN_TEXTURE, TEXEL_TOLERANCE, geometry_reason, near_plane};
use crate::gbuffer::GBuffer;
use crate::impostor::Impostor;
use crate::metrics::critical::CriticalPoints;
use crate::metrics::schaufler::{needs_finer_texture, resolution_for, sprite_still_valid, volume_centre};
use crate::predict::Predictor;
use crate::pyramid::Pyramid;
use crate::raster::rasterize;
use crate::warp::params::WarpParams;
use crate::warp::sprite::Sprite;
use crate::warp::texmap::volume_rect;
use crate::warp::{Method, draw, prepare};

/// A texture the manager wants made.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureRequest {
    pub id: u64,
    pub object: String,
    pub eye: Vec3,
    pub size: u32,
    pub depth_bits: DepthBits,
    /// `None`: needed now; `Some(ms)`: expected to be needed in `ms`.
    pub needed_in_ms: Option<u64>,
}

/// What the manager sends to whoever makes textures.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    Request(TextureRequest),
    Withdraw(Vec<u64>),
}

/// What comes back.
#[derive(Debug)]
pub enum Arrival {
    Texture {
        id: u64,
        /// Prepared where it arrived ([`Prepared::new`]), not in the frame loop.
        texture: Box<Prepared>,
        is_final: bool,
    },
    Failed {
        id: u64,
        reason: String,
    },
}

/// Tuning of the manager.
#[derive(Debug, Clone)]
pub struct Config {
    /// Largest growth of the predicted gap (worst of 8×8 regions, eq. 5-5…5-7, over
    /// the gaps at the texture's own eye), in screen pixels, before a texture counts
    /// as stale and a new one is needed.
    pub tolerance: f32,
    /// Ask for predicted textures (off: only when needed now).
    pub predict: bool,
    /// Round-trip estimate (seconds) before any request has been measured.
    pub initial_latency: f64,
    /// Textures kept per object.
    pub keep: usize,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            tolerance: 24.0,
            predict: true,
            initial_latency: 0.15,
            keep: 8,
        }
    }
}

/// A texture made ready for the frame loop: its pyramid (with texel connectivity),
/// critical points and the gaps it shows at its own eye. Building this takes
/// milliseconds for big textures, so the texture sources do it on their own threads.
pub struct Prepared {
    pyramid: Pyramid,
    critical: CriticalPoints,
    baseline: Vec<f32>,
}

impl Prepared {
    pub fn new(texture: ReliefTexture) -> Prepared {
        let critical = CriticalPoints::find(&texture, 8, 8);
        let baseline = WarpParams::new(&texture, texture.eye).map_or_else(
            |_| vec![0.0; critical.pairs.len()],
            |params| critical.region_gaps(&params),
        );
        Prepared {
            pyramid: Pyramid::new(texture, MIN_TEXTURE),
            critical,
            baseline,
        }
    }
}

impl std::fmt::Debug for Prepared {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.pyramid.levels[0].texture.camera;
        write!(f, "Prepared({}x{})", c.width, c.height)
    }
}

/// A texture held for an object.
struct Held {
    pyramid: Pyramid,
    critical: CriticalPoints,
    /// The regions' gaps at the texture's own eye: what it shows at best.
    baseline: Vec<f32>,
    eye: Vec3,
    is_final: bool,
}

#[derive(Debug, Clone, Copy)]
struct Pending {
    object: usize,
    eye: Vec3,
    predicted: bool,
    sent: Instant,
}

#[derive(Default)]
struct ObjectState {
    held: Vec<Held>,
    /// Angle (radians) over which the newest final texture of this object stays valid.
    valid_angle: Option<f32>,
    /// The last [`LATENCY_WINDOW`] round trips of this object's textures, seconds.
    recent_latencies: Vec<f64>,
    /// Textures of this object requested.
    requested: u64,
    /// Final textures of this object received.
    received: u64,
}

/// How well a held texture serves an eye.
#[derive(Debug, Clone, Copy)]
struct Grade {
    /// Growth of the widest predicted gap, screen pixels.
    growth: f32,
    /// Too coarse to be shown: its texels would cover more than [`COARSEST_SHOWN`]
    /// pixels (eq. 4-1).
    too_coarse: bool,
    /// … and a finer texture can be had (the largest asked for is 512²).
    coarse: bool,
}

/// Beyond this turn around the object, or this change of distance, a texture is not
/// used whatever the gap metric says: the metric sees holes between neighbours, not
/// the stretching of a view seen from far off its axis.
const MAX_TURN: f32 = 60.0 * std::f32::consts::PI / 180.0;
/// … and beyond this turn a texture drawn without a partner counts as stale (and one
/// for now is asked for): alone, it misses the side of the object the eye has turned
/// to see.
const LONE_MAX_TURN: f32 = 40.0 * std::f32::consts::PI / 180.0;
const MAX_DISTANCE_RATIO: f32 = 1.6;

/// How far past the predicted eye (a fraction of the valid angle) predicted textures
/// are made for: see [`Manager::lead`].
const LEAD: f32 = 0.5;

/// Predicted textures are asked for once the eye's future leaves this fraction of the
/// tolerance, so that a late answer or a wrong guess still finds the texture in use
/// within the tolerance itself.
const PLANNING_MARGIN: f32 = 0.75;

/// A texture whose texels would cover more than this many pixels' angle is not shown:
/// geometry is drawn instead while a finer texture is on its way — or, near an object
/// where even the largest texture is that coarse, while the eye stays that near.
const COARSEST_SHOWN: f32 = 2.0 * TEXEL_TOLERANCE;

/// A texture this many times over the tolerance is not shown: geometry is drawn
/// until a better one arrives (the frame still counts as stale).
const SHOWN_STALE: f32 = 2.0;

/// A partner (a second texture, drawn behind the shown one) is drawn once the eye is
/// this far around the object from the shown texture's eye: nearer, what the texture
/// cannot show is a sliver a pixel or two wide, not worth a second warp.
const PARTNER_FROM: f32 = 15.0 * std::f32::consts::PI / 180.0;

/// A partner is at most this far around the object from the eye: it fills in only
/// where the shown texture has nothing, so the stretching [`MAX_TURN`] guards against
/// shows only there.
const PARTNER_MAX_TURN: f32 = 2.0 * MAX_TURN;

/// Textures are asked for this many valid angles apart along the eye's turn, one
/// ahead of the eye's future at all times, so that the eye is always between two: the
/// nearer shown, the other its partner. (Below 2, the middle between two is within
/// [`PLANNING_MARGIN`] of the tolerance from both, so no request for coverage fires
/// there.)
const PAIR_SPACING: f32 = 2.0 * PLANNING_MARGIN;

/// How far behind the shown texture a partner is drawn: this fraction of the object's
/// bounding radius — more than two textures of one surface disagree on its depth
/// (depth quanta, reconstruction), so the partner shows only where the shown texture
/// has nothing (or something much farther).
const PARTNER_BEHIND: f32 = 0.05;

/// The depth factor (see [`Prepared::behind`](crate::warp::Prepared::behind)) that
/// puts a partner [`PARTNER_BEHIND`] behind, for an object with `bounds` seen from `eye`.
fn partner_depth_factor(bounds: &relief_core::bounds::Aabb, eye: Vec3) -> f32 {
    let radius = bounds.extent().length() * 0.5;
    let distance = bounds.center().distance(eye).max(radius).max(f32::MIN_POSITIVE);
    1.0 + PARTNER_BEHIND * radius / distance
}

/// Round trips remembered, and the percentile of them the predictor plans for.
const LATENCY_WINDOW: usize = 16;
/// Round trips of its own an object needs before it plans for them.
const OWN_LATENCIES: usize = 4;
const LATENCY_PERCENTILE: f64 = 0.9;
/// How far past the planned round trip predictions look: `--rtt-ms 100` demos, 4–8 runs
/// each (the path before its fly-through joined the orbit, ~375 frames): ×1.0 9.5
/// stale frames, ×1.25 7.1, ×1.5 7.5.
const HORIZON_SPARE: f64 = 1.25;

/// The growth (screen pixels) of `held`'s widest predicted gap when warped to `eye`.
fn growth(held: &Held, eye: Vec3, camera: &Camera) -> f32 {
    let texture = &held.pyramid.levels[0].texture;
    let c = &texture.camera;
    let centre = c.plane_centre();
    let middle = volume_centre(c);
    if angle_between(middle, held.eye, eye) > MAX_TURN || !similar_distance(middle, eye, held.eye) {
        return f32::INFINITY;
    }
    let Ok(params) = WarpParams::new(texture, eye) else {
        return f32::INFINITY;
    };
    let focal = camera.height as f32 / (2.0 * camera.tan_half_fov());
    // (At the image plane, the nearest the texture's surface comes: where a gap looks
    // widest.)
    let pixels_per_texel =
        c.a.length().max(c.b.length()) * focal / centre.distance(eye).max(f32::MIN_POSITIVE);
    held.critical.worst_growth(&params, &held.baseline) * pixels_per_texel
}

/// How an object is drawn this frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Show {
    Geometry,
    /// Held texture `texture`, pyramid level `level`; and a second held texture (with
    /// its level) drawn behind it, filling what the first cannot show from this eye.
    Impostor {
        texture: usize,
        level: usize,
        partner: Option<(usize, usize)>,
    },
}

/// The last image of an impostor, kept to be redrawn while the eye stays put.
struct Kept {
    sprite: Sprite,
    /// The eye it was drawn from.
    eye: Vec3,
    /// Which textures (by their eyes) and pyramid levels it shows.
    key: ShownKey,
}

/// The textures an impostor shows, by their eyes, and their pyramid levels: the
/// first, and the partner behind it.
type ShownKey = ((Vec3, usize), Option<(Vec3, usize)>);

/// Counters for the demo's summary.
#[derive(Debug, Clone, Default)]
pub struct Counters {
    /// Impostors redrawn as sprites (no warp) and impostors warped.
    pub sprites: u64,
    pub warps: u64,
    /// Partners warped (second textures drawn behind the shown one).
    pub partners: u64,
    /// Texels pre-warped, over all warps and partners (the shown texture at the
    /// pyramid level the screen needs, a partner one coarser; of those, the ones that
    /// can reach the screen): what a frame's impostors cost.
    pub texels_warped: u64,
    pub requests_now: u64,
    pub requests_predicted: u64,
    pub withdrawn: u64,
    /// Request → final texture, milliseconds.
    pub latencies_ms: Vec<f64>,
    /// Frames × objects where a valid texture was needed (impostors that may be on
    /// screen).
    pub needs: u64,
    /// … and one was there or already asked for.
    pub prediction_hits: u64,
    /// Frames where some impostor was shown above tolerance, alone too far from its
    /// eye, or missing.
    pub stale_frames: u64,
    /// Why: the object-frames without a valid texture, by cause.
    pub stale_causes: StaleCauses,
    /// Where each [`Manager::render`] spent its time.
    pub render_stages: Vec<RenderStages>,
}

/// Object-frames without a valid texture, by cause (the first that applies).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StaleCauses {
    /// No held texture can be warped to the eye at all: none held yet, or all too far
    /// round the object (past 60°) or at too different a distance.
    pub missing: u64,
    /// Some can, but none within the tolerance.
    pub beyond_tolerance: u64,
    /// One within tolerance, but shown alone more than 40° from its eye (no partner
    /// held to fill the side it misses).
    pub alone: u64,
}

/// Where one [`Manager::render`] spent its time, milliseconds.
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
}

/// The manager of one client.
pub struct Manager {
    config: Config,
    objects: Vec<ObjectState>,
    predictor: Predictor,
    pending: HashMap<u64, Pending>,
    next_id: u64,
    commands: UnboundedSender<Command>,
    arrivals: UnboundedReceiver<Arrival>,
    /// The last [`LATENCY_WINDOW`] round trips (request to final texture), seconds.
    recent_latencies: Vec<f64>,
    sprites: Vec<Option<Kept>>,
    /// The eye of the last frame drawn.
    last_eye: Option<Vec3>,
    pub counters: Counters,
}

/// How far (radians) around `centre`, turning the texture's eye about the vertical,
/// `held` stays within `tolerance`: probed at doubling angles, then halved back.
fn probe_valid_angle(held: &Held, centre: Vec3, camera: &Camera, tolerance: f32) -> f32 {
    let within = |angle: f32| {
        [angle, -angle].iter().all(|&a| {
            let eye = centre + glam::Quat::from_rotation_y(a) * (held.eye - centre);
            growth(held, eye, camera) <= tolerance
        })
    };
    let mut angle = 0.5f32.to_radians();
    while angle < std::f32::consts::FRAC_PI_2 && within(angle * 2.0) {
        angle *= 2.0;
    }
    // Refine between `angle` (within) and twice it (not).
    let (mut lo, mut hi) = (angle, angle * 2.0);
    for _ in 0..4 {
        let mid = 0.5 * (lo + hi);
        if within(mid) { lo = mid } else { hi = mid }
    }
    lo
}

/// Which of an object's held textures (graded `grades` at the eye, `turn(i)` radians
/// round the object from it) is shown: of those fine enough for the screen, the one
/// nearest the eye within `tolerance`, else the one with the least growth. (The
/// growth metric sees gaps, not the side of the object a texture from far round
/// cannot show: a sphere's growth is about 0 from anywhere.)
fn shown_texture(grades: &[Grade], tolerance: f32, turn: impl Fn(usize) -> f32) -> Option<(usize, Grade)> {
    let tolerated = |g: &Grade| g.growth <= tolerance;
    grades
        .iter()
        .copied()
        .enumerate()
        .filter(|(_, g)| !g.too_coarse)
        .min_by(|(i, a), (j, b)| {
            tolerated(b).cmp(&tolerated(a)).then_with(|| match tolerated(a) {
                true => turn(*i).total_cmp(&turn(*j)),
                false => a.growth.total_cmp(&b.growth),
            })
        })
}

/// Whether one of an object's held textures (`held`: eye and grade at `future`)
/// covers the eye `future` (all about `centre`), as prediction plans it: within the
/// planning margin of `tolerance`, not too coarse with a finer one to be had, and
/// within the planning margin of the turn a texture may be shown alone — or up to
/// [`MAX_TURN`] with a partner there, held (fine enough to be drawn there, as drawing
/// requires) or asked for (`asked`).
fn held_covers(centre: Vec3, future: Vec3, held: &[(Vec3, Grade)], asked: &[Vec3], tolerance: f32) -> bool {
    let partners = held
        .iter()
        .filter(|(_, g)| !g.too_coarse)
        .map(|(eye, _)| *eye)
        .chain(asked.iter().copied());
    let partnered = |shown: Vec3| {
        partners
            .clone()
            .any(|other| can_partner(centre, shown, future, other))
    };
    held.iter().any(|&(eye, g)| {
        let turn = angle_between(centre, eye, future);
        g.growth <= PLANNING_MARGIN * tolerance
            && !g.coarse
            && (turn <= PLANNING_MARGIN * LONE_MAX_TURN || (turn <= MAX_TURN && partnered(eye)))
    })
}

/// The texture edges the manager asks for: half-octave steps from 32 to 512 (the odd
/// steps, 32·√2^k, rounded to multiples of 8). With power-of-two edges a texture had up
/// to 4× the texels the screen can show, each warped every frame; here at most 2.1×
/// (edges ≤ 1.46× what is needed).
const TEXTURE_LADDER: [u32; 9] = [32, 48, 64, 88, 128, 184, 256, 360, 512];

/// The smallest edge of the [`TEXTURE_LADDER`] that holds `need` texels, the largest
/// when `need` is beyond.
pub fn texture_ladder(need: u32) -> u32 {
    let largest = TEXTURE_LADDER[TEXTURE_LADDER.len() - 1];
    TEXTURE_LADDER
        .into_iter()
        .find(|&edge| edge >= need)
        .unwrap_or(largest)
}

/// The angle at `centre` between two eyes.
fn angle_between(centre: Vec3, a: Vec3, b: Vec3) -> f32 {
    (a - centre).angle_between(b - centre)
}

/// Whether `a` is within [`MAX_DISTANCE_RATIO`] of `b`'s distance from `centre`.
fn similar_distance(centre: Vec3, a: Vec3, b: Vec3) -> bool {
    let ratio = (a - centre).length() / (b - centre).length();
    (1.0 / MAX_DISTANCE_RATIO..=MAX_DISTANCE_RATIO).contains(&ratio)
}

/// Whether a texture made from `other` can partner one made from `shown` at `eye`
/// (all about `centre`): on the far side of the eye, the way it has turned from
/// `shown`, within [`PARTNER_MAX_TURN`] of the eye and at a similar distance.
fn can_partner(centre: Vec3, shown: Vec3, eye: Vec3, other: Vec3) -> bool {
    let (from, eye, other) = (shown - centre, eye - centre, other - centre);
    from.cross(eye).dot(eye.cross(other)) > 0.0
        && other.angle_between(eye) <= PARTNER_MAX_TURN
        && similar_distance(Vec3::ZERO, eye, other)
}

/// `offset` from `centre` turned by `angle` about `axis` (not zero), as a point.
fn turned(centre: Vec3, offset: Vec3, axis: Vec3, angle: f32) -> Vec3 {
    centre + glam::Quat::from_axis_angle(axis.normalize(), angle) * offset
}

impl Manager {
    pub fn new(
        scene: &Scene,
        config: Config,
        commands: UnboundedSender<Command>,
        arrivals: UnboundedReceiver<Arrival>,
    ) -> Self {
        Manager {
            recent_latencies: Vec::new(),
            config,
            objects: scene.objects.iter().map(|_| ObjectState::default()).collect(),
            predictor: Predictor::default(),
            pending: HashMap::new(),
            next_id: 1,
            commands,
            arrivals,
            sprites: Vec::new(),
            last_eye: None,
            counters: Counters::default(),
        }
    }

    /// The round trip to plan for: the [`LATENCY_PERCENTILE`] of the recent ones (the
    /// configured estimate before any). Round trips vary several-fold with the
    /// workers' queue; planning for a typical one would leave every slower one stalled.
    /// An object with [`OWN_LATENCIES`] round trips of its own plans for those: a heavy
    /// object takes longer to trace than the rest.
    fn latency(&self, object: usize) -> f64 {
        let own = &self.objects[object].recent_latencies;
        let recent = if own.len() >= OWN_LATENCIES {
            own
        } else {
            &self.recent_latencies
        };
        if recent.is_empty() {
            return self.config.initial_latency;
        }
        crate::stats::percentile(recent, LATENCY_PERCENTILE)
    }

    /// Textures requested per object so far.
    pub fn requested(&self, object: usize) -> u64 {
        self.objects.get(object).map_or(0, |o| o.requested)
    }

    /// Final textures received per object so far: the regenerations.
    pub fn received(&self, object: usize) -> u64 {
        self.objects.get(object).map_or(0, |o| o.received)
    }

    /// Textures held, over all objects: none after a whole run means none ever came.
    pub fn textures_held(&self) -> usize {
        self.objects.iter().map(|o| o.held.len()).sum()
    }

    /// The held texture `texture` of `object`.
    pub fn pyramid(&self, object: usize, texture: usize) -> &Pyramid {
        &self.objects[object].held[texture].pyramid
    }

    /// Draws a frame as [`Manager::frame`] decided: each impostor redrawn as the
    /// sprite it was last frame while Schaufler's test holds (no warp), else warped
    /// (falling back to geometry where a warp is refused); geometry rasterized; one
    /// shading pass.
    pub fn render(&mut self, scene: &Scene, shows: &[Show], camera: &Camera, gbuffer: &mut GBuffer) -> Frame {
        let start = Instant::now();
        gbuffer.clear();
        self.sprites.resize_with(scene.objects.len(), || None);
        // Which impostors are redrawn as sprites and which warped: the warps' pre-warps
        // all run at once, then everything is drawn in order.
        let keys: Vec<Option<ShownKey>> = shows
            .iter()
            .enumerate()
            .map(|(k, show)| match *show {
                Show::Impostor {
                    texture,
                    level,
                    partner,
                } => {
                    // (A `Show` from before textures arrived or were dropped names textures
                    // no longer held: drawn as geometry, or without its partner.)
                    let held = &self.objects[k].held;
                    let shown = (held.get(texture)?.eye, level);
                    Some((shown, partner.and_then(|(p, l)| Some((held.get(p)?.eye, l)))))
                }
                Show::Geometry => None,
            })
            .collect();
        let sprite_holds: Vec<bool> = keys
            .iter()
            .enumerate()
            .map(|(k, key)| match (key, &self.sprites[k]) {
                (Some(key), Some(kept)) => {
                    kept.key == *key && sprite_still_valid(&scene.objects[k].bounds, kept.eye, camera)
                }
                _ => false,
            })
            .collect();
        // The textures to warp: each impostor's, its partner right after it.
        let mut warps: Vec<(usize, &Impostor, bool)> = Vec::new();
        for (k, show) in shows.iter().enumerate() {
            if let Show::Impostor {
                texture,
                level,
                partner,
            } = *show
                && !sprite_holds[k]
            {
                let at = |(texture, level): (usize, usize)| {
                    self.objects[k].held.get(texture)?.pyramid.levels.get(level)
                };
                let Some(shown) = at((texture, level)) else {
                    continue;
                };
                warps.push((k, shown, false));
                if let Some(partner) = partner.and_then(at) {
                    warps.push((k, partner, true));
                }
            }
        }
        let behind = |k: usize| partner_depth_factor(&scene.objects[k].bounds, camera.eye);
        let prepared: Vec<_> = warps
            .par_iter()
            .map(|&(k, impostor, is_partner)| {
                let prepared = prepare(Method::Interleaved, impostor, camera);
                if is_partner {
                    prepared.and_then(|p| p.behind(behind(k)))
                } else {
                    prepared
                }
            })
            .collect();
        let prewarps_done = Instant::now();
        // (Only those pre-warped: an eye in or behind a texture's plane is refused first.)
        self.counters.texels_warped += (warps.iter().zip(&prepared))
            .map(|((_, impostor, _), ready)| ready.as_ref().map_or(0, |p| p.texels_warped(impostor)) as u64)
            .sum::<u64>();
        let mut prepared = warps.into_iter().zip(prepared).peekable();
        let mut geometry: Vec<(u32, &SceneObject)> = Vec::new();
        for (k, key) in keys.into_iter().enumerate() {
            let Some(key) = key else {
                self.sprites[k] = None;
                geometry.push((k as u32, &scene.objects[k]));
                continue;
            };
            if sprite_holds[k]
                && let Some(kept) = &self.sprites[k]
            {
                kept.sprite.draw(gbuffer);
                self.counters.sprites += 1;
                continue;
            }
            // The impostor's warp, then its partner's (whose failure only leaves out
            // what it would have filled in).
            let (mut rect, mut partner_drawn): (Option<(u32, u32, u32, u32)>, bool) = (None, false);
            while let Some(((_, impostor, is_partner), ready)) = prepared.next_if(|((j, _, _), _)| *j == k) {
                if is_partner && rect.is_none() {
                    continue;
                }
                if ready
                    .and_then(|p| draw(p, impostor, k as u32, camera, gbuffer))
                    .is_ok()
                {
                    partner_drawn |= is_partner;
                    self.counters.partners += u64::from(is_partner);
                    let r = volume_rect(camera, &impostor.texture.camera);
                    rect = Some(rect.map_or(r, |q| (q.0.min(r.0), q.1.min(r.1), q.2.max(r.2), q.3.max(r.3))));
                }
            }
            // (The sprite says what it shows: without a partner that failed to draw.)
            let key = (key.0, key.1.filter(|_| partner_drawn));
            let Some(rect) = rect else {
                self.sprites[k] = None;
                geometry.push((k as u32, &scene.objects[k]));
                continue;
            };
            self.counters.warps += 1;
            // Kept only while the eye moves by less than the sprite test allows
            // per frame (or has not moved yet): else the next frame warps anyway,
            // and the copy (1.2 of a flight's 8 ms per frame) is wasted.
            let bounds = &scene.objects[k].bounds;
            if self
                .last_eye
                .is_some_and(|eye| !sprite_still_valid(bounds, eye, camera))
            {
                self.sprites[k] = None;
                continue;
            }
            self.sprites[k] = Sprite::capture_in(gbuffer, k as u32, rect).map(|sprite| Kept {
                sprite,
                eye: camera.eye,
                key,
            });
        }
        self.last_eye = Some(camera.eye);
        let impostors_done = Instant::now();
        rasterize(&geometry, camera, near_plane(scene), gbuffer);
        let geometry_done = Instant::now();
        let frame = gbuffer.shade(scene, camera);
        let ms = |from: Instant, to: Instant| (to - from).as_secs_f64() * 1e3;
        self.counters.render_stages.push(RenderStages {
            prewarp_ms: ms(start, prewarps_done),
            draw_ms: ms(prewarps_done, impostors_done),
            geometry_ms: ms(impostors_done, geometry_done),
            shade_ms: ms(geometry_done, Instant::now()),
        });
        frame
    }

    /// Takes in what has arrived (never waits).
    fn drain(&mut self, camera: &Camera, scene: &Scene) {
        let eye = camera.eye;
        while let Ok(arrival) = self.arrivals.try_recv() {
            match arrival {
                Arrival::Texture {
                    id,
                    texture,
                    is_final,
                } => {
                    let Some(p) = self.pending.get(&id).copied() else {
                        continue; // Withdrawn meanwhile.
                    };
                    if is_final {
                        self.pending.remove(&id);
                        let ms = p.sent.elapsed().as_secs_f64() * 1e3;
                        self.counters.latencies_ms.push(ms);
                        tracing::debug!(object = p.object, ms, predicted = p.predicted, "round trip");
                        for recent in [
                            &mut self.recent_latencies,
                            &mut self.objects[p.object].recent_latencies,
                        ] {
                            recent.push(ms / 1e3);
                            if recent.len() > LATENCY_WINDOW {
                                recent.remove(0);
                            }
                        }
                    }
                    let Prepared {
                        pyramid,
                        critical,
                        baseline,
                    } = *texture;
                    let state = &mut self.objects[p.object];
                    state.received += is_final as u64;
                    // A final texture replaces its own preview.
                    state.held.retain(|h| h.is_final || h.eye != p.eye);
                    let held = Held {
                        eye: p.eye,
                        pyramid,
                        critical,
                        baseline,
                        is_final,
                    };
                    if is_final {
                        let centre = scene.objects[p.object].bounds.center();
                        let angle = probe_valid_angle(&held, centre, camera, self.config.tolerance);
                        state.valid_angle = Some(angle);
                        tracing::debug!(
                            object = p.object,
                            valid_deg = angle.to_degrees(),
                            "texture arrived; its valid angle probed"
                        );
                    }
                    state.held.push(held);
                    // Keep the textures nearest the eye.
                    if state.held.len() > self.config.keep {
                        let centre = scene.objects[p.object].bounds.center();
                        state.held.sort_by(|a, b| {
                            angle_between(centre, a.eye, eye).total_cmp(&angle_between(centre, b.eye, eye))
                        });
                        state.held.truncate(self.config.keep);
                    }
                }
                Arrival::Failed { id, reason } => {
                    // (A withdrawn request's end is no news.)
                    if self.pending.remove(&id).is_some() {
                        tracing::warn!("texture request {id} failed: {reason}");
                    }
                }
            }
        }
    }

    /// How each held texture of `object` would do warped to `eye`: the growth of its
    /// widest predicted gap over the gaps it has at its own eye, in screen pixels
    /// (`INFINITY` when it cannot be warped there), whether it is too coarse to be
    /// shown, and whether a finer one can be had (eq. 4-1).
    fn grades<'a>(
        &'a self,
        scene: &Scene,
        object: usize,
        eye: Vec3,
        camera: &'a Camera,
    ) -> impl Iterator<Item = Grade> + 'a {
        let wanted = Self::size_for(&scene.objects[object], eye, camera);
        let at_eye = Camera { eye, ..*camera };
        self.objects[object].held.iter().map(move |h| {
            let texture = &h.pyramid.levels[0].texture.camera;
            let too_coarse = needs_finer_texture(texture, &at_eye, COARSEST_SHOWN);
            Grade {
                growth: growth(h, eye, camera),
                too_coarse,
                coarse: too_coarse && texture.width < wanted,
            }
        })
    }

    /// The angle around an object over which its newest texture stays within tolerance.
    fn valid_angle(&self, object: usize) -> f32 {
        self.objects[object].valid_angle.unwrap_or(4f32.to_radians())
    }

    /// Whether a request already out for `object` will serve `eye`.
    fn pending_covers(&self, object: usize, centre: Vec3, eye: Vec3) -> bool {
        let reach = 0.8 * self.valid_angle(object);
        self.pending.values().any(|p| {
            p.object == object
                && angle_between(centre, p.eye, eye) < reach
                && ((p.eye - centre).length() / (eye - centre).length() - 1.0).abs() < 0.2
        })
    }

    /// The texture edge to ask for: what the screen can show of the object from `eye`
    /// ([`resolution_for`], eq. 5-1), rounded up to the [`texture_ladder`].
    fn size_for(object: &SceneObject, eye: Vec3, camera: &Camera) -> u32 {
        texture_ladder(resolution_for(&object.bounds, eye, camera, TEXEL_TOLERANCE).unwrap_or(u32::MAX))
    }

    fn request(
        &mut self,
        scene: &Scene,
        object: usize,
        eye: Vec3,
        camera: &Camera,
        needed_in_ms: Option<u64>,
    ) {
        let o = &scene.objects[object];
        let size = Self::size_for(o, eye, camera);
        let id = self.next_id;
        self.next_id += 1;
        let request = TextureRequest {
            id,
            object: o.name.clone(),
            eye,
            size,
            depth_bits: DepthBits::Eight,
            needed_in_ms,
        };
        if self.commands.send(Command::Request(request)).is_err() {
            return;
        }
        self.pending.insert(
            id,
            Pending {
                object,
                eye,
                predicted: needed_in_ms.is_some(),
                sent: Instant::now(),
            },
        );
        self.objects[object].requested += 1;
        match needed_in_ms {
            Some(_) => self.counters.requests_predicted += 1,
            None => self.counters.requests_now += 1,
        }
    }

    /// Before the first frame: asks for the textures `camera` needs and waits (at most
    /// `limit`) until they are all there, so a flight starts with its impostors ready.
    /// Returns whether they all arrived. Counters start afresh afterwards.
    pub fn warm_up(&mut self, scene: &Scene, camera: &Camera, limit: std::time::Duration) -> bool {
        let start = Instant::now();
        let ready = loop {
            let before = self.counters.stale_frames;
            self.frame(scene, camera, 0.0);
            // Previews make a frame valid before the final textures are in; a final
            // arriving after the flight started would count its cold-start round trip
            // as the flight's and make the predictor plan for it.
            if self.counters.stale_frames == before && self.pending.is_empty() {
                break true;
            }
            if start.elapsed() > limit {
                break false;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        };
        self.predictor = Predictor::default();
        self.counters = Counters::default();
        // The cold start's round trips (scene upload, every object at once) say
        // little about the flight's.
        self.recent_latencies.clear();
        for o in &mut self.objects {
            o.recent_latencies.clear();
            o.requested = 0;
            o.received = 0;
        }
        ready
    }

    /// Decides how each object is drawn from `camera` at time `t` (seconds), asking for
    /// textures as needed. Never blocks.
    pub fn frame(&mut self, scene: &Scene, camera: &Camera, t: f64) -> Vec<Show> {
        self.drain(camera, scene);
        self.predictor.observe(t, camera.eye);
        let mut stale = false;
        let mut shows = Vec::with_capacity(scene.objects.len());
        for (k, object) in scene.objects.iter().enumerate() {
            match geometry_reason(object, camera.eye) {
                Some(GeometryReason::Cheap) => {
                    shows.push(Show::Geometry);
                    continue;
                }
                Some(GeometryReason::TooNear) => {
                    // Drawn as geometry while the eye is this near, but the eye will
                    // leave: have its textures ready by then.
                    self.predict_for(scene, k, camera);
                    shows.push(Show::Geometry);
                    continue;
                }
                None => {}
            }
            if !camera.may_see(&object.bounds) {
                // Off screen: nothing shown, so nothing stale and nothing needed now
                // (drawn as geometry, which the rasterizer leaves out at once); the
                // textures for where the eye is going are still asked for.
                self.predict_for(scene, k, camera);
                shows.push(Show::Geometry);
                continue;
            }
            let centre = object.bounds.center();
            let grades: Vec<Grade> = self.grades(scene, k, camera.eye, camera).collect();
            self.counters.needs += 1;
            let held = &self.objects[k].held;
            let best = shown_texture(&grades, self.config.tolerance, |i| {
                angle_between(centre, held[i].eye, camera.eye)
            });
            let within =
                |g: Option<(usize, Grade)>| g.is_some_and(|(_, g)| g.growth <= self.config.tolerance);
            // Valid: some texture is within tolerance (when only one too coarse to be
            // shown is, a finer one is asked for if it can be had: `coarse`), and the one
            // shown is not alone too far from its eye — without a partner, a texture
            // more than [`LONE_MAX_TURN`] from its eye misses the side the eye has
            // turned to.
            let shown_turn = best.map(|(i, _)| angle_between(centre, held[i].eye, camera.eye));
            let partner = best.and_then(|(i, _)| self.partner(k, i, centre, camera, &grades));
            let lone_too_far = partner.is_none() && shown_turn.is_some_and(|turn| turn > LONE_MAX_TURN);
            let within_any = grades.iter().any(|g| g.growth <= self.config.tolerance);
            let valid = within_any && !lone_too_far;
            let coarse = !within(best)
                && grades
                    .iter()
                    .any(|g| g.growth <= self.config.tolerance && g.coarse);
            let asked_for = self.pending_covers(k, centre, camera.eye);
            if valid || asked_for {
                self.counters.prediction_hits += 1;
            }
            if !valid {
                let causes = &mut self.counters.stale_causes;
                if grades.iter().all(|g| g.growth == f32::INFINITY) {
                    causes.missing += 1;
                } else if within(best) {
                    causes.alone += 1;
                } else {
                    causes.beyond_tolerance += 1;
                }
                if tracing::enabled!(tracing::Level::DEBUG) {
                    // What was asked for: (age ms, predicted, degrees from this eye).
                    let asked: Vec<(u128, bool, f32)> = self
                        .pending
                        .values()
                        .filter(|p| p.object == k)
                        .map(|p| {
                            let degrees = angle_between(centre, p.eye, camera.eye).to_degrees();
                            (p.sent.elapsed().as_millis(), p.predicted, degrees)
                        })
                        .collect();
                    let shown_deg = shown_turn.map(f32::to_degrees);
                    tracing::debug!(
                        object = %object.name,
                        growth = best.map(|b| b.1.growth),
                        shown_deg,
                        lone_too_far,
                        held = self.objects[k].held.len(),
                        valid_deg = self.valid_angle(k).to_degrees(),
                        planned_latency_s = self.latency(k),
                        ?asked,
                        "stale"
                    );
                }
                stale = true;
            }
            // One request for now in flight per object: when textures stay valid for
            // less than the eye takes to leave them, a request each frame would only
            // queue textures that are stale on arrival.
            let asking_now = self.pending.values().any(|p| p.object == k && !p.predicted);
            if (!valid || coarse) && !asked_for && !asking_now {
                self.request(scene, k, camera.eye, camera, None);
            }
            self.predict_for(scene, k, camera);
            shows.push(match best {
                Some((i, g)) if g.growth <= SHOWN_STALE * self.config.tolerance => {
                    let level = self.objects[k].held[i].pyramid.level_for(camera, TEXEL_TOLERANCE);
                    Show::Impostor {
                        texture: i,
                        level,
                        partner,
                    }
                }
                _ => Show::Geometry,
            });
        }
        if stale {
            self.counters.stale_frames += 1;
        }
        shows
    }

    /// The texture (and its level) to draw behind object `k`'s shown texture `shown`,
    /// with `grades` at this eye: a held one on the far side of the eye, the way it has
    /// turned from `shown`'s eye, fine enough, within [`PARTNER_MAX_TURN`] of the eye
    /// and [`MAX_DISTANCE_RATIO`] of its distance — it holds what the eye has turned to
    /// see and `shown` cannot. The least growth first, then the nearest (past
    /// [`MAX_TURN`] every growth is infinite). `None` while the eye is within
    /// [`PARTNER_FROM`] of `shown`'s.
    fn partner(
        &self,
        k: usize,
        shown: usize,
        centre: Vec3,
        camera: &Camera,
        grades: &[Grade],
    ) -> Option<(usize, usize)> {
        let held = &self.objects[k].held;
        let (from, eye) = (held[shown].eye - centre, camera.eye - centre);
        if from.angle_between(eye) < PARTNER_FROM {
            return None;
        }
        held.iter()
            .zip(grades)
            .enumerate()
            .filter_map(|(i, (h, g))| {
                let usable =
                    i != shown && !g.too_coarse && can_partner(centre, held[shown].eye, camera.eye, h.eye);
                usable.then_some((i, h, g.growth, (h.eye - centre).angle_between(eye)))
            })
            .min_by(|a, b| a.2.total_cmp(&b.2).then(a.3.total_cmp(&b.3)))
            .map(|(i, h, _, _)| {
                // One level coarser than the screen needs: it shows only slivers, and
                // its pre-warp costs a quarter.
                let level = h.pyramid.level_for(camera, TEXEL_TOLERANCE) + 1;
                (i, level.min(h.pyramid.levels.len() - 1))
            })
    }

    /// Whether object `k` has a texture held or asked for on the far side of `future`
    /// (the way the eye turns from `now`), to partner the one shown there — and if not,
    /// the eye to ask for one at: [`PAIR_SPACING`] valid angles past `future`. `None`
    /// while the eye is not turning about the object. (This keeps partners coming
    /// along the motion; [`can_partner`] is the test of one pair of textures at one
    /// eye, by which side of the eye each is on, whatever the motion.)
    fn ahead(&self, k: usize, centre: Vec3, now: Vec3, future: Vec3) -> Option<Result<(), Vec3>> {
        let (from, to) = (now - centre, future - centre);
        let axis = from.cross(to);
        // (Below ~0.06° of turn per horizon, "ahead" means nothing.)
        if axis.length() <= 1e-3 * from.length() * to.length() {
            return None;
        }
        let reach = PAIR_SPACING * self.valid_angle(k);
        // (Held or asked for within half as far again — an eye asked for `reach` ahead
        // falls a little beyond it as the future moves on, or as the eye's elevation
        // tilts the turn — and at a distance [`Self::partner`] accepts.)
        let ahead = |eye: Vec3| {
            let e = eye - centre;
            axis.dot(to.cross(e)) > 0.0
                && to.angle_between(e) <= 1.5 * reach
                && similar_distance(centre, future, eye)
        };
        let held = self.objects[k].held.iter().any(|h| ahead(h.eye));
        let asked = self.pending.values().any(|p| p.object == k && ahead(p.eye));
        Some(if held || asked {
            Ok(())
        } else {
            Err(turned(centre, to, axis, reach))
        })
    }

    /// The eye to make a predicted texture for: `future` turned further about `centre`,
    /// the way the eye turns from `now`, by [`LEAD`] of the object's valid angle (at
    /// most the turn from `now` to `future` again). The texture is then first used
    /// [`LEAD`]·valid behind its own eye and stays in use as far ahead: it serves
    /// (1 + [`LEAD`]) valid angles of the motion instead of one.
    fn lead(&self, k: usize, centre: Vec3, now: Vec3, future: Vec3) -> Vec3 {
        let (from, to) = (now - centre, future - centre);
        let axis = from.cross(to);
        let turn = from.angle_between(to);
        let lead = (LEAD * self.valid_angle(k)).min(turn);
        if turn.is_nan() || lead <= 1e-4 || axis.length_squared() <= f32::MIN_POSITIVE {
            return future;
        }
        turned(centre, to, axis, lead)
    }

    /// Asks ahead (when predicting) for the texture the eye will need once a request
    /// for object `k` made now comes back, and withdraws predictions the motion has
    /// left behind.
    fn predict_for(&mut self, scene: &Scene, k: usize, camera: &Camera) {
        if !self.config.predict {
            return;
        }
        // The round trip to plan for, with a quarter and 50 ms to spare (arrivals later
        // than the recent 90th percentile were most of a flight's stale frames), and
        // the eye then.
        let horizon = (HORIZON_SPARE * self.latency(k) + 0.05).min(3.0);
        let Some(future) = self.predictor.predict(horizon) else {
            return;
        };
        let object = &scene.objects[k];
        let centre = object.bounds.center();
        // Drawn as geometry from there: nothing to ask for.
        if geometry_reason(object, future) == Some(GeometryReason::TooNear) {
            return;
        }
        let held: Vec<(Vec3, Grade)> = (self.objects[k].held.iter().map(|h| h.eye))
            .zip(self.grades(scene, k, future, camera))
            .collect();
        let asked: Vec<Vec3> = (self.pending.values())
            .filter(|p| p.object == k)
            .map(|p| p.eye)
            .collect();
        let covered = held_covers(centre, future, &held, &asked, self.config.tolerance)
            || self.pending_covers(k, centre, future);
        let ahead = self.ahead(k, centre, camera.eye, future);
        let deadline = Some((horizon * 1e3) as u64);
        if !covered {
            let eye = self.lead(k, centre, camera.eye, future);
            self.request(scene, k, eye, camera, deadline);
        } else if let Some(Err(eye)) = ahead {
            self.request(scene, k, eye, camera, deadline);
        }
        // Predictions neither the eye nor its future will meet any more.
        let reach = 2.0 * self.valid_angle(k);
        let stale: Vec<u64> = self
            .pending
            .iter()
            .filter(|(_, p)| p.object == k && p.predicted)
            .filter(|(_, p)| {
                angle_between(centre, p.eye, camera.eye) > reach
                    && angle_between(centre, p.eye, future) > reach
            })
            .map(|(&id, _)| id)
            .collect();
        if !stale.is_empty() {
            for id in &stale {
                self.pending.remove(id);
            }
            self.counters.withdrawn += stale.len() as u64;
            let _ = self.commands.send(Command::Withdraw(stale));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The texture shown among four with these growths, turns 0.7, 0.1, 0.05 and 0.3
    /// from the eye; the third (the nearest) too coarse to be shown. Tolerance 4.
    fn shown(growths: [f32; 4]) -> Option<usize> {
        let turns = [0.7, 0.1, 0.05, 0.3];
        let mut grades = growths.map(|growth| Grade {
            growth,
            too_coarse: false,
            coarse: false,
        });
        grades[2].too_coarse = true;
        shown_texture(&grades, 4.0, |i| turns[i]).map(|s| s.0)
    }

    /// Prediction counts a texture 40° from the future eye as covering it only with a
    /// partner on the far side that could be drawn there: one too coarse at that eye
    /// does not count (drawing would not use it), one asked for does.
    #[test]
    fn a_partner_too_coarse_to_draw_does_not_cover_the_future() {
        let around = |degrees: f32| {
            let a = degrees.to_radians();
            Vec3::new(6.0 * a.cos(), 0.0, 6.0 * a.sin())
        };
        // (Too coarse, and a finer one to be had: not shown there either.)
        let grade = |too_coarse| Grade {
            growth: 0.0,
            too_coarse,
            coarse: too_coarse,
        };
        let future = around(40.0);
        let covers = |partner_too_coarse, asked: &[Vec3]| {
            let held = [
                (around(0.0), grade(false)),
                (around(75.0), grade(partner_too_coarse)),
            ];
            held_covers(Vec3::ZERO, future, &held, asked, 4.0)
        };
        assert!(covers(false, &[]));
        assert!(!covers(true, &[]));
        assert!(covers(true, &[around(60.0)]));
        // Near a held texture's own eye no partner is needed.
        let near = [(around(35.0), grade(false))];
        assert!(held_covers(Vec3::ZERO, future, &near, &[], 4.0));
    }

    #[test]
    fn the_texture_shown_is_the_nearest_within_tolerance_else_the_least_grown() {
        // 1 is nearer than 0, whose growth is less (2 is nearer still, but too coarse).
        assert_eq!(shown([0.0, 2.0, 0.0, 9.0]), Some(1));
        // Only 3 within tolerance, though farther than 1.
        assert_eq!(shown([7.0, 6.0, 0.0, 3.0]), Some(3));
        // None within: the least grown, wherever it is.
        assert_eq!(shown([5.0, 8.0, 0.0, f32::INFINITY]), Some(0));
        // Only a too coarse one: none.
        let coarse = Grade {
            growth: 0.0,
            too_coarse: true,
            coarse: false,
        };
        assert!(shown_texture(&[coarse], 4.0, |_| 0.0).is_none());
    }
}
