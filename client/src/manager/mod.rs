//! The impostor manager: per object and frame, decide geometry or impostor (and which
//! texture), keep a cache of relief textures, and ask for the textures the eye will
//! need — predicted ahead of need, early enough to cover the measured round trip —
//! without ever waiting for the network.
//!
//! The principal type is [`Manager`]; every tuning constant it obeys is in [`policy`].
//!
//! # Each frame
//!
//! [`Manager::frame`] takes in what has arrived (`cache.rs`), then for each object
//! decides a [`Show`]: geometry (cheap objects, an eye too near, nothing held that can
//! be shown), or a held texture — of those within the tolerance and fine enough for the
//! screen, the one whose eye is nearest (`choose.rs`) — with, once the eye has turned far
//! enough from it, a *partner* drawn behind it: a texture from the far side of the eye
//! that fills in the side of the object the first cannot show. It asks for a texture
//! for now when none is valid, and for the textures the eye will need (`requests.rs`):
//! orthographic for solids, unless theirs fell short of what their own eye sees
//! (`perspective.rs`).
//! [`Manager::render`] then draws the frame as decided (`draw.rs`).
//!
//! # Textures in and out
//!
//! Requests and withdrawals go out as [`Command`]s on one channel; textures and
//! failures come back as [`Arrival`]s on another (`messages.rs`) — whoever serves them
//! (a server over gRPC, or the in-process generator: [`crate::source`]) works on its
//! own threads. Nothing the manager does waits on them.
//!
//! # Counting
//!
//! [`Counters`] hold what a run's summary reports: requests, round trips, needs met,
//! stale frames by cause, draws, and each frame's stage times (`counters.rs`).
//!
//! Asked to ([`Manager::sample_warps`]), the manager also keeps about one in K of its
//! pre-warps with their textures and cameras, to be timed again on their own
//! (`warp_samples.rs`).
//!
//! The [crate's overview](crate) has an example.

mod around;
mod cache;
mod choose;
mod counters;
mod draw;
mod link_scale;
mod messages;
mod perspective;
pub mod policy;
mod requests;
mod warp_samples;

use std::collections::HashMap;
use std::time::{Duration, Instant};

use rayon::prelude::*;
use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender};

use relief_core::camera::Camera;
use relief_core::scene::{Scene, SceneObject};
use relief_render::geometry::{GeometryReason, geometry_reason};

use crate::predict::{Predictor, view_of};

pub(crate) use cache::Prepared;
pub use cache::ReadyTexture;
pub use choose::{Show, ShownTexture};
pub use counters::{Counters, RenderStages, StaleCauses, TextureLifetimes, late_fraction};
pub use messages::{Arrival, Command, Failure, TextureRequest};
pub use policy::Config;
pub use requests::texture_ladder;
pub use warp_samples::WarpSample;

use around::angle_between;
use cache::ObjectState;
use choose::{Grade, may_show, shown_texture};
use draw::Kept;
use policy::{ASSESSMENTS_PER_TASK, SHOWN_STALE, WARM_UP_POLL, cheaper_as_geometry, texel_pixels};
use requests::{Asked, Pending};
use warp_samples::WarpSampler;

/// The manager of one client: what it holds and has asked for per object, where the eye
/// is going, the channels to its texture source, and what it has counted.
pub struct Manager {
    config: Config,
    /// Per scene object: the textures held, its valid angle, its round trips.
    objects: Vec<ObjectState>,
    predictor: Predictor,
    /// Requests out, by id.
    pending: HashMap<u64, Pending>,
    next_id: u64,
    commands: UnboundedSender<Command>,
    arrivals: UnboundedReceiver<Arrival>,
    /// The last [`LATENCY_WINDOW`](policy::LATENCY_WINDOW) round trips (request to
    /// final texture) of all objects, seconds.
    recent_latencies: Vec<f64>,
    /// Per object, its last image, kept to be redrawn while the sprite test holds.
    sprites: Vec<Option<Kept>>,
    /// The camera of the last frame drawn.
    last_camera: Option<Camera>,
    /// When the last frame was planned: what it relied on is kept (see
    /// [`Manager::hold`]).
    planned_at: Instant,
    /// The factor the server's load puts on the tolerance (1: none; see
    /// [`policy::LOAD_HIGH_WAIT`]).
    load_scale: f32,
    /// The server's load as last heard (see [`Manager::server_wait`]).
    server_wait: Duration,
    /// The shortest round trip lately: the link's factor on the tolerance.
    round_trip_floor: link_scale::RoundTripFloor,
    /// While warming up ([`Manager::warm_up`]), the latest it ends: the flight starts
    /// no sooner than what was asked for is in, so nothing is needed before then.
    warm_up_until: Option<Instant>,
    /// What this run counted.
    pub counters: Counters,
    /// The pre-warps kept to be timed again, when asked ([`Manager::sample_warps`]).
    warp_samples: Option<WarpSampler>,
}

impl Manager {
    /// A manager of `scene`'s objects that asks for textures on `commands` and takes
    /// them from `arrivals` (both ends served by a [`source`](crate::source)).
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
            last_camera: None,
            planned_at: Instant::now(),
            load_scale: 1.0,
            server_wait: Duration::ZERO,
            round_trip_floor: link_scale::RoundTripFloor::default(),
            warm_up_until: None,
            counters: Counters::default(),
            warp_samples: None,
        }
    }

    /// Final textures received per object so far: the regenerations.
    pub fn received(&self, object: usize) -> u64 {
        self.objects.get(object).map_or(0, |o| o.received)
    }

    /// Textures held, over all objects: none after a whole run means none ever came.
    pub fn textures_held(&self) -> usize {
        self.objects.iter().map(|o| o.held.len()).sum()
    }

    /// The tolerance decisions use now: the user's, times the factors the server's load
    /// and the link put on it ([`Manager::load_scale`], [`Manager::link_scale`];
    /// together at most [`policy::MAX_LOAD_SCALE`]).
    pub fn tolerance(&self) -> f32 {
        self.config.tolerance * (self.load_scale * self.link_scale()).min(policy::MAX_LOAD_SCALE)
    }

    /// The factor a link with long round trips puts on the user's tolerance: the shortest
    /// round trip lately over [`policy::LINK_TUNED_ROUND_TRIP`], at least 1 (see the
    /// `link_scale` module).
    pub fn link_scale(&self) -> f32 {
        self.round_trip_floor.scale()
    }

    /// The factor the server's load puts on the user's tolerance now (see
    /// [`policy::LOAD_HIGH_WAIT`]); 1 on an unloaded server.
    pub fn load_scale(&self) -> f32 {
        self.load_scale
    }

    /// The server's load as the last look at it heard ([`Link::look`](crate::link::Link::look),
    /// every [`HEALTH_POLL`](crate::link::HEALTH_POLL)): the wait it foresaw for a new
    /// job behind the others (its `queue_wait_ms`), or, a look it was too busy to answer,
    /// [`HEALTH_POLL_TIMEOUT`](crate::link::HEALTH_POLL_TIMEOUT). Zero until heard.
    pub fn server_wait(&self) -> Duration {
        self.server_wait
    }

    /// Takes the server's load in, as a look heard it ([`Manager::server_wait`]): a
    /// long wait for a new job's slot raises the tolerance a step, a short one lowers it
    /// a step.
    fn feel_load(&mut self, wait: Duration) {
        self.server_wait = wait;
        let stepped = if wait > policy::LOAD_HIGH_WAIT {
            self.load_scale * policy::LOAD_STEP_UP
        } else if wait < policy::LOAD_LOW_WAIT {
            (self.load_scale / policy::LOAD_STEP_DOWN).max(1.0)
        } else {
            self.load_scale
        };
        // Within the bound with the link's factor (at most the bound itself, so this is
        // at least 1): past it, a factor the tolerance no longer shows would take its
        // steps down unseen.
        self.load_scale = stepped.min(policy::MAX_LOAD_SCALE / self.link_scale());
        tracing::debug!(
            wait_ms = wait.as_millis() as u64,
            scale = self.load_scale,
            "server load"
        );
    }

    /// Requests asked for and not yet ended (by their final texture, a failure or a
    /// withdrawal): at the end of a run, the work it leaves unanswered.
    pub fn requests_open(&self) -> usize {
        self.pending.len()
    }

    /// Before the first frame: asks for the textures each of `cameras` needs — the
    /// first frame's first, then any the flight will soon need — and waits (at most
    /// `limit`) until they are all there, so a flight starts with its impostors ready.
    /// Returns whether they all arrived (`true` at once for no camera). Counters start
    /// afresh afterwards.
    ///
    /// Predictions are made from the first camera only: the predictor sees one eye
    /// while warming up, and from the others' views they would be made for it, asked
    /// from one view and withdrawn by the next, never all in.
    pub fn warm_up(&mut self, scene: &Scene, cameras: &[Camera], limit: std::time::Duration) -> bool {
        let start = Instant::now();
        self.warm_up_until = Some(start + limit);
        let ready = loop {
            let before = self.counters.stale_frames;
            for (k, camera) in cameras.iter().enumerate() {
                self.plan(scene, camera, 0.0, self.config.predict && k == 0);
            }
            // Previews fine enough to be shown make a frame valid before the final
            // textures are in; a final arriving after the flight started would count its
            // cold-start round trip as the flight's and make the predictor plan for it.
            if self.counters.stale_frames == before && self.pending.is_empty() {
                break true;
            }
            if start.elapsed() > limit {
                // What it asked for ahead is needed no sooner than the warm-up may last
                // (see `Manager::predict_for`): come during the flight, its round trips
                // of seconds would be planned for. The flight asks afresh.
                self.withdraw_predicted(|_| true);
                break false;
            }
            std::thread::sleep(WARM_UP_POLL);
        };
        self.warm_up_until = None;
        self.predictor = Predictor::default();
        self.counters = Counters::default();
        // The cold start's round trips (scene upload, every object at once) say
        // little about the flight's.
        self.recent_latencies.clear();
        for o in &mut self.objects {
            o.recent_latencies.clear();
            o.received = 0;
        }
        ready
    }

    /// Decides how each object is drawn from `camera` at time `t` (seconds), asking for
    /// textures as needed. Never blocks.
    pub fn frame(&mut self, scene: &Scene, camera: &Camera, t: f64) -> Vec<Show> {
        self.plan(scene, camera, t, self.config.predict)
    }

    /// [`Manager::frame`], asking ahead only where `predict` holds.
    fn plan(&mut self, scene: &Scene, camera: &Camera, t: f64, predict: bool) -> Vec<Show> {
        self.drain(camera, scene);
        let tolerance = self.tolerance();
        self.predictor.observe(t, camera.eye, view_of(camera));
        let mut stale = false;
        // (When this frame shows its impostors: their textures' last use.)
        let now = Instant::now();
        self.planned_at = now;
        let shown_at = Some(now);
        let mut shows = vec![Show::Geometry; scene.objects.len()];
        let world_camera = camera;
        // Every object assessed, and its prediction worked out, before any is decided
        // about: they only read, and grading each held texture (its critical points'
        // growth) at the eye and where it is going is most of a frame's plan — on all
        // cores once there are enough objects to share ([`ASSESSMENTS_PER_TASK`]).
        let assess_and_predict = |&k: &usize| {
            let assessment = self.assess(scene, k, world_camera);
            let prediction = (predict && assessment.reason != Some(GeometryReason::Cheap))
                .then(|| self.prediction(scene, k, &assessment.camera, world_camera))
                .flatten();
            (k, assessment, prediction)
        };
        let order = nearest_first(scene, world_camera);
        let mut stand_in_triangles = self.config.stand_in_triangles;
        let assessed: Vec<_> = (order.par_iter().with_min_len(ASSESSMENTS_PER_TASK))
            .map(assess_and_predict)
            .collect();
        for (k, assessment, prediction) in assessed {
            let object = &scene.objects[k];
            // Each object is decided about in its own frame (see `SceneObject`).
            let camera = &assessment.camera;
            match assessment.reason {
                Some(GeometryReason::Cheap) => continue,
                Some(GeometryReason::TooNear) => {
                    // Drawn as geometry while the eye is this near, but the eye will
                    // leave: have its textures ready by then.
                    self.predict_for(scene, k, camera, prediction);
                    continue;
                }
                None => {}
            }
            let Some(grades) = assessment.grades else {
                // Off screen (nothing shown, so nothing stale and nothing needed now:
                // drawn as geometry, which the rasterizer leaves out at once), or drawn
                // as geometry while its texture would cost more than it: the textures
                // for where the eye is going are still asked for, if a view from there
                // would show it (see `Manager::prediction`).
                self.predict_for(scene, k, camera, prediction);
                continue;
            };
            let (centre, eye) = (object.local_bounds.center(), camera.eye_f32());
            self.counters.needs += 1;
            let held = &self.objects[k].held;
            let best = shown_texture(&grades, tolerance, |i| angle_between(centre, held[i].eye, eye));
            let within = |g: Option<(usize, Grade)>| g.is_some_and(|(_, g)| g.growth <= tolerance);
            // Valid: the texture shown is within tolerance (where only one too coarse to
            // be shown is, the frame is not valid: a finer one is asked for, `want_finer`,
            // and meanwhile the object stands in as geometry or is stale — unless none
            // finer can be had, below), and not too far from its eye for it to be shown
            // alone or with the partner it has: alone, a texture misses the side the eye
            // has turned to see (`may_show`).
            let shown_turn = best.map(|(i, _)| angle_between(centre, held[i].eye, eye));
            let partner = best.and_then(|(i, _)| self.partner(k, i, centre, camera, &grades));
            let too_far = best.zip(shown_turn).is_some_and(|((_, g), turn)| {
                !may_show(g.unshown, turn, g.lone_turn, partner.is_some(), 1.0, tolerance)
            });
            // Where the one within tolerance is too coarse to be shown and nothing
            // finer can be had (the largest texture, the eye near), geometry is drawn
            // while the eye stays that near (`policy::COARSEST_SHOWN`): valid, as asking
            // again would bring the same.
            let none_finer = !within(best)
                && grades
                    .iter()
                    .any(|g| g.growth <= tolerance && g.too_coarse && !g.finer_available);
            let valid = (within(best) && !too_far) || none_finer;
            // Without a valid texture, drawn exactly as geometry where it still fits in
            // the frame's triangles to spare for that (`Config::stand_in_triangles`):
            // not stale.
            let triangles = object.mesh.triangle_count();
            let stands_in = !valid && stand_in_triangles > 0 && triangles <= stand_in_triangles;
            if stands_in {
                stand_in_triangles -= triangles;
            }
            // A finer texture is asked for while the shown one is still shown, once its
            // texels grow past `REFINE_TEXEL` (the eye drawing near), as when the only
            // one within tolerance is too coarse to be shown at all.
            let finer_wanted = |g: &Grade| g.growth <= tolerance && g.finer_available;
            let want_finer = best.is_some_and(|(_, g)| finer_wanted(&g))
                || (!within(best) && grades.iter().any(finer_wanted));
            let asked_for = self.pending_covers(scene, k, centre, eye);
            if valid || asked_for != Asked::Not {
                self.counters.prediction_hits += 1;
            }
            if stands_in {
                self.counters.stand_ins += 1;
            } else if !valid {
                let causes = &mut self.counters.stale_causes;
                if grades.iter().all(|g| g.growth == f32::INFINITY) {
                    causes.missing += 1;
                } else if within(best) {
                    causes.too_far += 1;
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
                            let degrees = angle_between(centre, p.eye, eye).to_degrees();
                            (p.sent.elapsed().as_millis(), p.predicted(), degrees)
                        })
                        .collect();
                    let shown_deg = shown_turn.map(f32::to_degrees);
                    // What is held: (age ms, degrees from this eye, gap growth px; a
                    // texture seen from too far round, or too far off its distance, grows
                    // without bound).
                    let held: Vec<(u128, f32, f32)> = (self.objects[k].held.iter().zip(&grades))
                        .map(|(h, g)| {
                            let degrees = angle_between(centre, h.eye, eye).to_degrees();
                            (h.arrived.elapsed().as_millis(), degrees, g.growth)
                        })
                        .collect();
                    tracing::debug!(
                        object = %object.name,
                        growth = best.map(|b| b.1.growth),
                        shown_deg,
                        too_far,
                        valid_deg = self.valid_angle(k).to_degrees(),
                        planned_latency_s = self.latency(k),
                        ?asked,
                        ?held,
                        "stale"
                    );
                }
                stale = true;
            }
            // One request for now in flight per object: when textures stay valid for
            // less than the eye takes to leave them, a request each frame would only
            // queue textures that are stale on arrival. A stale object asks now even when
            // only a prediction out covers the eye: that prediction is late, and the
            // request for now joins its job on the server and moves it ahead of the
            // predicted work there (or, not near enough to join, is baked first itself).
            // So does one standing in as geometry: exact meanwhile, but up to the
            // frame's whole budget of triangles (a rock) for as long as it waits.
            let asking_now = self.pending.values().any(|p| p.object == k && !p.predicted());
            let wanted = match asked_for {
                Asked::Not => !valid || want_finer,
                Asked::Predicted => !valid,
                Asked::Now => false,
            };
            if wanted && !asking_now {
                self.request(scene, k, eye, camera, None);
            }
            self.predict_for(scene, k, camera, prediction);
            shows[k] = match best {
                Some((i, g)) if !stands_in && !none_finer && g.growth <= SHOWN_STALE * tolerance => {
                    self.objects[k].last_shown = shown_at;
                    let in_perspective = self.objects[k].in_perspective;
                    let held = &mut self.objects[k].held;
                    for j in std::iter::once(i).chain(partner.map(|(p, _)| p)) {
                        held[j].last_shown = shown_at;
                        held[j].relied_on = now;
                    }
                    let level = held[i]
                        .prepared
                        .pyramid
                        .level_for(camera, texel_pixels(&scene.objects[k], camera, in_perspective));
                    Show::Impostor {
                        texture: i,
                        level,
                        partner,
                    }
                }
                _ => Show::Geometry,
            };
        }
        if stale {
            self.counters.stale_frames += 1;
        }
        self.counters.load_scale_sum += f64::from(self.load_scale);
        self.counters.link_scale_sum += f64::from(self.link_scale());
        shows
    }
}

/// What a frame knows of an object before deciding about it ([`Manager::assess`]).
struct Assessment {
    /// The frame's camera in the object's frame (see `SceneObject`).
    camera: Camera,
    /// Why it is drawn as geometry, whatever the textures.
    reason: Option<GeometryReason>,
    /// Each held texture's grade at the eye (in the order held: the frame adds and
    /// drops none before it decides), where it may be shown: on screen, and its
    /// texture no dearer to warp than its triangles to draw ([`Manager::grades`]);
    /// `None` elsewhere.
    grades: Option<Vec<Grade>>,
}

impl Manager {
    /// Whether `object` is drawn as geometry from `world_camera` whatever textures are
    /// held: too near or too cheap ([`geometry_reason`]), or no dearer drawn than the
    /// texture its eye would ask for warped (`Manager::warped_edge`, [`cheaper_as_geometry`]).
    pub fn always_geometry(object: &SceneObject, world_camera: &Camera) -> bool {
        if geometry_reason(object, world_camera.eye).is_some() {
            return true;
        }
        let camera = object.local_camera(world_camera);
        // (As for an object whose textures are asked orthographic: the edge differs
        // little either way.)
        Self::warped_edge(object, camera.eye_f32(), &camera, false).is_none()
    }

    /// The edge of the texture an `eye` (in `object`'s frame, as `camera` is) asks for,
    /// where warping it costs more than drawing `object` as geometry
    /// ([`cheaper_as_geometry`]); `None` where it does not.
    pub(super) fn warped_edge(
        object: &SceneObject,
        eye: glam::Vec3,
        camera: &Camera,
        in_perspective: bool,
    ) -> Option<u32> {
        let (wanted, _) = Self::size_for(object, eye, camera, in_perspective);
        (!cheaper_as_geometry(object, wanted)).then_some(wanted)
    }

    /// Object `k` seen from `world_camera`: its camera, and how its textures grade.
    fn assess(&self, scene: &Scene, k: usize, world_camera: &Camera) -> Assessment {
        let object = &scene.objects[k];
        let camera = object.local_camera(world_camera);
        let reason = geometry_reason(object, world_camera.eye);
        let grades = (reason.is_none() && camera.may_see(&object.local_bounds))
            .then(|| self.grades(scene, k, camera.eye_f32(), &camera))
            .flatten();
        Assessment {
            camera,
            reason,
            grades,
        }
    }
}

/// The scene's objects, nearest the eye of `camera` first (by their bounds' centres):
/// the order a frame decides about them in, and so the order its requests go out in —
/// a server serves requests alike in urgency first come, first served, and in a scene
/// of hundreds of objects the near ones, large on screen, should not wait behind the
/// far ones.
fn nearest_first(scene: &Scene, camera: &Camera) -> Vec<usize> {
    let distance = |o: &relief_core::scene::SceneObject| {
        o.world_bounds().center().as_dvec3().distance_squared(camera.eye)
    };
    let mut order: Vec<(f64, usize)> = (scene.objects.iter()).map(distance).zip(0..).collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0));
    order.into_iter().map(|(_, k)| k).collect()
}
