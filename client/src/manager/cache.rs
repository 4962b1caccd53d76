//! The textures held for each object: arrivals taken in (never waiting), a solid's
//! orthographic ones weighed at their own eye (`perspective.rs`), each final one's
//! valid angle probed, those relied on and then the nearest the eye kept, and each
//! shared with the other placements of its mesh that can show it.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::relief::ReliefTexture;
use relief_core::scene::Scene;
use relief_render::impostor::Faces;
use relief_render::pyramid::Pyramid;
use relief_render::validity::critical::CriticalPoints;
use relief_render::validity::edges::EdgeError;
use relief_render::validity::rim::Rim;
use relief_render::warp::params::WarpParams;

use super::around::{angle_between, similar_distance};
use super::choose::{growth, widest_within};
use super::messages::{Arrival, Failure};
use super::perspective::{ShortTextures, weighed};
use super::policy::{CRITICAL_REGIONS, MIN_LEVEL_EDGE, SHED_QUIET, growth_weight};
use super::{Manager, TextureLifetimes};

/// What making a texture ready builds: its pyramid (with texel connectivity), critical
/// points, its neighbours' gaps at its own eye, its rim and the weight of its gaps'
/// growth. One per texture, shared by every placement and every client in a process
/// that holds it (see [`Manager::share`], [`crate::intake`]).
pub(crate) struct Prepared {
    pub(super) pyramid: Pyramid,
    pub(super) critical: CriticalPoints,
    /// The regions' pairs' gaps at the texture's own eye, from which their growth counts
    /// (`CriticalPoints::worst_growth`; the hidden surfaces' counts whole).
    pub(super) baseline: Vec<f32>,
    /// Its rim's curvature: the band past the outline it cannot show from a turned eye.
    pub(super) rim: Rim,
    /// What a pixel of its gaps' growth counts for ([`growth_weight`]).
    pub(super) growth_weight: f32,
}

/// A texture made ready for the frame loop — its pyramid (with texel connectivity),
/// critical points, its neighbours' gaps at its own eye, its rim and the weight of its
/// gaps' growth, shared by every client in a process given the same texture (see
/// [`crate::intake`]) — and when it reached the client. Building it takes milliseconds
/// for big textures, so the texture sources do it on their own threads.
#[derive(Clone)]
pub struct ReadyTexture {
    prepared: Arc<Prepared>,
    /// When the texture reached the client, before it was made ready.
    arrived: Instant,
}

impl ReadyTexture {
    /// Makes `texture`, which has just reached the client, ready for the frame loop,
    /// showing `faces` of its object's surfaces.
    pub fn new(texture: ReliefTexture, faces: Faces) -> ReadyTexture {
        ReadyTexture::arrived_at(texture, faces, Instant::now())
    }

    /// [`ReadyTexture::new`] for a texture that reached the client at `arrived`.
    pub fn arrived_at(texture: ReliefTexture, faces: Faces, arrived: Instant) -> ReadyTexture {
        let critical = CriticalPoints::find(&texture, CRITICAL_REGIONS, CRITICAL_REGIONS);
        let baseline = WarpParams::without_tables(&texture, texture.eye).map_or_else(
            |_| vec![0.0; critical.pairs.len()],
            |params| critical.pair_gaps(&params),
        );
        let pyramid = Pyramid::new(texture, MIN_LEVEL_EDGE).with_faces(faces);
        let prepared = Prepared {
            rim: Rim::find(&pyramid.levels[0].texture),
            growth_weight: growth_weight(EdgeError::of(&pyramid.levels[0])),
            pyramid,
            critical,
            baseline,
        };
        ReadyTexture::shared(Arc::new(prepared), arrived)
    }

    /// A texture made ready already (`prepared`), reached a client at `arrived`.
    pub(crate) fn shared(prepared: Arc<Prepared>, arrived: Instant) -> ReadyTexture {
        ReadyTexture { prepared, arrived }
    }

    /// What making it ready built.
    pub(crate) fn prepared(&self) -> &Arc<Prepared> {
        &self.prepared
    }

    /// When it reached the client.
    pub fn arrived(&self) -> Instant {
        self.arrived
    }
}

impl std::fmt::Debug for ReadyTexture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.prepared.pyramid.levels[0].texture.camera;
        write!(f, "ReadyTexture({}x{})", c.width, c.height)
    }
}

/// A texture held for an object. (Placements of one mesh hold one texture alike, what
/// was made ready shared: see [`Manager::share`].)
#[derive(Clone)]
pub(super) struct Held {
    pub(super) prepared: Arc<Prepared>,
    pub(super) eye: Vec3,
    pub(super) is_final: bool,
    /// When it reached the client, and the last frame it was shown in (as the shown
    /// texture or a partner): its lifetime.
    pub(super) arrived: Instant,
    pub(super) last_shown: Option<Instant>,
    /// When a frame took it in (after its decoding): the first frame that could show it.
    pub(super) taken_in: Instant,
    /// When the manager last relied on it: took it in, showed it, or counted it (or a
    /// partner it needs) as covering where the eye is going (a prediction's future
    /// eye). What the last frame relied on is kept first (see
    /// [`Manager::hold`]).
    pub(super) relied_on: Instant,
    /// Asked for by another placement of the mesh, and shared with this one: counted
    /// in that placement's lifetimes, not here.
    pub(super) shared: bool,
    /// An orthographic texture that falls short of what its own eye sees
    /// ([`OWN_EYE_GROWTH`](super::policy::OWN_EYE_GROWTH)): let go once its object's
    /// textures are asked in perspective, where one can be asked from its eye
    /// (`perspective.rs`).
    pub(super) falls_short: bool,
}

#[derive(Default)]
pub(super) struct ObjectState {
    pub(super) held: Vec<Held>,
    /// Angle (radians) over which the newest final texture of this object stays valid.
    pub(super) valid_angle: Option<f32>,
    /// The last [`LATENCY_WINDOW`] round trips of this object's textures, seconds.
    pub(super) recent_latencies: Vec<f64>,
    /// Final textures of this object received.
    pub(super) received: u64,
    /// The last frame it was shown in, from any of its textures.
    pub(super) last_shown: Option<Instant>,
    /// No new prediction of it is asked for before this (see [`SHED_QUIET`]).
    pub(super) quiet_until: Option<Instant>,
    /// Its textures are asked in perspective: orthographic ones fell short of what
    /// their own eye sees (`perspective.rs`).
    pub(super) in_perspective: bool,
    /// Which of its last orthographic textures fell short so.
    pub(super) short_textures: ShortTextures,
}

/// How far (radians) around `centre`, turning the texture's eye about the vertical,
/// `held` stays within `tolerance` ([`widest_within`]).
pub(super) fn probe_valid_angle(held: &Held, centre: Vec3, camera: &Camera, tolerance: f32) -> f32 {
    widest_within(|angle: f32| {
        [angle, -angle].iter().all(|&a| {
            let eye = centre + glam::Quat::from_rotation_y(a) * (held.eye - centre);
            growth(held, eye, camera) <= tolerance
        })
    })
}

impl Manager {
    /// Takes in what has arrived (never waits).
    pub(super) fn drain(&mut self, camera: &Camera, scene: &Scene) {
        // The server's load reports that queued up while no frame ran (a slow frame, a
        // load-test client waiting for the others) count as one, the latest: each steps
        // the tolerance's factor, and a backlog taken in at once stepped it to its bound.
        let mut load = None;
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
                    let ReadyTexture { prepared, arrived } = *texture;
                    if is_final {
                        self.pending.remove(&id);
                        self.record_round_trip(&p, arrived);
                    }
                    let tolerance = self.tolerance();
                    let object = &scene.objects[p.object];
                    let state = &mut self.objects[p.object];
                    state.received += is_final as u64;
                    // Its own eye: one the server made for a nearby eye serves too (see
                    // `SERVE_REACH`).
                    let eye = prepared.pyramid.levels[0].texture.eye;
                    let edge = |p: &Prepared| p.pyramid.levels[0].texture.camera.width;
                    let new_edge = edge(&prepared);
                    // Held already, as fine: the texture that served another request.
                    let answered = |h: &Held| h.is_final && h.eye == eye && edge(&h.prepared) >= new_edge;
                    if let Some(held) = state.held.iter_mut().find(|h| answered(h)) {
                        held.relied_on = Instant::now();
                        // (Received again if asked for again since it came, and not when
                        // one bake answers two requests at once, their jobs merged.)
                        let again = is_final && p.sent > held.taken_in && weighed(held, object);
                        let short = held.falls_short;
                        if again {
                            self.count_short(p.object, object, short);
                        }
                        continue;
                    }
                    let taken_in = Instant::now();
                    let mut held = Held {
                        eye,
                        prepared,
                        is_final,
                        arrived,
                        last_shown: None,
                        taken_in,
                        relied_on: taken_in,
                        shared: false,
                        falls_short: false,
                    };
                    let (local, centre) = (object.local_camera(camera), object.local_bounds.center());
                    // (Before it replaces anything: one let go leaves what it would have
                    // replaced in place.)
                    if !self.weigh_own_eye((p.object, p.eye), object, &mut held, &local) {
                        continue;
                    }
                    let state = &mut self.objects[p.object];
                    // A final texture replaces its own preview, and a coarser one from its
                    // eye (a finer one asked for as the texels grew: `REFINE_TEXEL`).
                    let (replaced, kept): (Vec<Held>, Vec<Held>) =
                        std::mem::take(&mut state.held).into_iter().partition(|h| {
                            h.eye == eye && (!h.is_final || (is_final && edge(&h.prepared) < new_edge))
                        });
                    state.held = kept;
                    for h in &replaced {
                        self.counters.retired.retire(h, state.last_shown);
                    }
                    if is_final {
                        let angle = probe_valid_angle(&held, centre, &local, tolerance);
                        state.valid_angle = Some(angle);
                        let texture = &held.prepared.pyramid.levels[0].texture;
                        tracing::debug!(
                            object = p.object,
                            valid_deg = angle.to_degrees(),
                            eye = ?texture.eye,
                            edge = texture.camera.width.max(texture.camera.height),
                            perspective = texture.camera.centre.is_some(),
                            hidden = texture.hidden.len(),
                            "texture arrived; its valid angle probed"
                        );
                        self.share(scene, camera, p.object, &held, angle);
                    }
                    self.hold(p.object, held, centre, local.eye_f32());
                }
                Arrival::ServerLoad { wait } => load = Some(wait),
                Arrival::LinkRoundTrip { round_trip } => {
                    self.round_trip_floor
                        .record(round_trip.as_secs_f64() * 1e3, Instant::now());
                }
                Arrival::Failed { id, failure } => {
                    // (A withdrawn request's end is no news.)
                    let Some(pending) = self.pending.remove(&id) else {
                        continue;
                    };
                    let counted = match failure {
                        Failure::Refused(_) => &mut self.counters.requests_failed,
                        Failure::TimedOut(_) => &mut self.counters.requests_timed_out,
                        // (The load's own signal, counted: not news worth a line.)
                        Failure::Shed(_) => {
                            self.counters.requests_shed += 1;
                            // (Quiet only while the server reports itself saturated: a
                            // refusal in a passing burst is asked again at once.)
                            if self.load_scale > 1.0 {
                                self.objects[pending.object].quiet_until = Some(Instant::now() + SHED_QUIET);
                            }
                            continue;
                        }
                    };
                    *counted += 1;
                    // The first of a run on stderr; the rest are counted (a server gone
                    // for a while fails every request, and one line each buried the
                    // rest). Needed again, a texture is asked for again.
                    if self.counters.requests_failed + self.counters.requests_timed_out == 1 {
                        tracing::warn!(
                            "texture request {id} failed: {failure} (further failures are counted, not shown)"
                        );
                    } else {
                        tracing::debug!("texture request {id} failed: {failure}");
                    }
                }
            }
        }
        if let Some(wait) = load {
            self.feel_load(wait);
        }
    }
}

impl Manager {
    /// Holds `held` for object `k`, keeping, of more than
    /// [`TEXTURES_KEPT`](super::policy::TEXTURES_KEPT), those taken in or relied on
    /// since the last frame was planned ([`Held::relied_on`]), then those nearest its eye
    /// (`eye`, about `centre`, in its frame). (Kept by nearness alone, when a texture
    /// was also asked for to partner the shown one a pair of valid angles beyond the
    /// eye's future, that one — the farthest held — went as it came, unseen, and was
    /// asked for again the next frame: in one default run, the sphere's 20 times
    /// running on its near pass.)
    fn hold(&mut self, k: usize, held: Held, centre: Vec3, eye: Vec3) {
        let since = self.planned_at;
        let state = &mut self.objects[k];
        state.held.push(held);
        if state.held.len() > self.config.keep {
            state.held.sort_by(|a, b| {
                let (a_old, b_old) = (a.relied_on < since, b.relied_on < since);
                let away = |h: &Held| angle_between(centre, h.eye, eye);
                a_old.cmp(&b_old).then_with(|| away(a).total_cmp(&away(b)))
            });
            for retired in state.held.split_off(self.config.keep) {
                self.counters.retired.retire(&retired, state.last_shown);
            }
        }
    }

    /// Shares object `from`'s new final texture `held`, valid over `angle` about its
    /// eye, with the other placements of its mesh that can show it: those whose eye
    /// (in the mesh's frame, where the texture is) lies within that angle of its own at
    /// a similar distance, and that hold nothing nearer. Each then holds it as if it had
    /// asked (its pyramid shared, not copied), and asks for none of its own.
    fn share(&mut self, scene: &Scene, camera: &Camera, from: usize, held: &Held, angle: f32) {
        let mesh = &scene.objects[from];
        let centre = mesh.local_bounds.center();
        for (j, other) in scene.objects.iter().enumerate() {
            if j == from || !other.shares_mesh(mesh) {
                continue;
            }
            let eye = other.to_local(camera.eye);
            let turn = angle_between(centre, held.eye, eye);
            let nearer_held =
                (self.objects[j].held.iter()).any(|h| angle_between(centre, h.eye, eye) <= turn);
            if turn > angle || !similar_distance(centre, held.eye, eye) || nearer_held {
                continue;
            }
            let shared = Held {
                shared: true,
                ..held.clone()
            };
            self.hold(j, shared, centre, eye);
            self.objects[j].valid_angle.get_or_insert(angle);
            self.counters.textures_shared += 1;
        }
    }

    /// The lifetimes of the run's final textures so far: those no longer held, and
    /// those held now.
    pub fn texture_lifetimes(&self) -> TextureLifetimes {
        let mut lifetimes = self.counters.retired.clone();
        for object in &self.objects {
            for held in &object.held {
                lifetimes.retire(held, object.last_shown);
            }
        }
        lifetimes
    }
}
