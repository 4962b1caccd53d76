//! A real-time flight along a scene's camera path with the impostor manager: the one
//! frame loop of `relief demo`, `render` and the load test's clients.
//!
//! # The clock
//!
//! The eye follows the clock ([`FlightClock`]): it is where the path is `t·fps` frames
//! after the start. A slow frame does not slow the eye down — the next one shows it
//! further on, and the path frames between are skipped — so a predictor sees the true
//! motion, and latency is real.
//!
//! # Example
//!
//! ```no_run
//! # use relief_client::{flight::Flight, manager::Manager};
//! # fn demo(scene: &relief_core::scene::Scene, manager: &mut Manager) -> Result<(), relief_core::camera::CameraError> {
//! let flight = Flight { scene, size: (640, 360), fps: 30, frames: 240, start: 0, wrap: false };
//! flight.warm_up(manager)?;
//! let log = flight.fly(manager, |_| true, |flown| {
//!     // `flown.image` is the frame drawn: show it, write it, compare it …
//!     Ok::<_, relief_core::camera::CameraError>(std::ops::ControlFlow::Continue(()))
//! })?;
//! println!("{} frames, {:?} regenerations per orbit", log.frames, log.regenerations_per_orbit());
//! # Ok(()) }
//! ```

use std::collections::BTreeMap;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

use glam::DVec3;

use relief_core::camera::{Camera, CameraError, PathSegment};
use relief_core::frame::Frame;
use relief_core::scene::Scene;
use relief_render::gbuffer::GBuffer;
use relief_render::geometry::is_cheap;

use crate::manager::{Manager, ShownTexture};

/// Paces a flight of `frames` path frames at `fps`, the eye following the clock (see
/// [the module](self)).
pub struct FlightClock {
    start: Instant,
    fps: u32,
    frames: u32,
    next_frame: u32,
}

impl FlightClock {
    /// Starts the clock now.
    pub fn start(fps: u32, frames: u32) -> FlightClock {
        FlightClock {
            start: Instant::now(),
            fps: fps.max(1),
            frames,
            next_frame: 0,
        }
    }
}

impl Iterator for FlightClock {
    /// `(t, position)`: seconds since the start, and the path position in frames.
    type Item = (f64, f64);

    /// Waits until the next path frame is due; `None` once the path is flown.
    fn next(&mut self) -> Option<(f64, f64)> {
        let due = Duration::from_secs_f64(self.next_frame as f64 / self.fps as f64);
        if let Some(wait) = due.checked_sub(self.start.elapsed()) {
            std::thread::sleep(wait);
        }
        let t = self.start.elapsed().as_secs_f64();
        let position = t * self.fps as f64;
        if position >= self.frames as f64 {
            return None;
        }
        self.next_frame = position as u32 + 1;
        Some((t, position))
    }
}

/// How long a flight waits for the textures of its first frame (and those
/// [`WARM_UP_AHEAD_S`] in) before it starts anyway: a cold start traces every object
/// at once, seconds for the default scene's rock.
pub const WARM_UP_LIMIT: Duration = Duration::from_secs(20);

/// Seconds into the flight whose views are warmed up for too, beside the first frame's:
/// the flight's predictions come a round trip after it sets off, and the predictor
/// needs a few frames of motion first. (Warmed up for the first frame alone, the
/// default demo's knot, orbited at 45° a second, went stale 0.5–0.7 s in, past its
/// first texture's valid angle, in about half the flights over a 100 ms link with 2 %
/// loss; with views in its first second, in none of 28. At 0.5 and 1 s, 22° apart
/// round the knot, wider than its textures' valid angle, the two views' textures
/// counted as covering the eye's future, so nothing was predicted between them, and
/// the knot 0.17 s in was drawn between the two, 3.7 dB below geometry. A quarter of a
/// second apart, they are 11°.) Only one request for now is out per object, so a cold
/// start's textures of an object come one after another: the warm-up lasts longer.
pub const WARM_UP_AHEAD_S: [f64; 4] = [0.25, 0.5, 0.75, 1.0];

/// A flight: which path, how fast, how long, at what frame size.
#[derive(Clone, Copy)]
pub struct Flight<'a> {
    /// The scene, whose camera path is flown.
    pub scene: &'a Scene,
    /// Frame size, pixels.
    pub size: (u32, u32),
    /// Path frames per second.
    pub fps: u32,
    /// Path frames to fly.
    pub frames: u32,
    /// The path frame the flight starts at.
    pub start: u32,
    /// Past the path's end, start it again (else stay at its last frame).
    pub wrap: bool,
}

/// One frame of a flight, as [`Flight::fly`] hands it over.
pub struct Flown<'a> {
    /// Frames flown before this one.
    pub index: u32,
    /// The path frame shown.
    pub path_frame: u32,
    /// Seconds since the flight started.
    pub t: f64,
    pub camera: &'a Camera,
    /// The frame, when it was drawn.
    pub image: Option<Frame>,
    /// How each object of the scene was drawn (by index): the texture shown, or `None`
    /// for geometry.
    pub shown: Vec<Option<ShownTexture>>,
}

/// What the manager did and heard in one frame flown: told second by second, whether a
/// flight's stale frames were a passing episode or its steady state, and what the
/// server's load was meanwhile.
#[derive(Debug, Clone, Copy, Default)]
pub struct FrameRecord {
    /// The camera path's frame it showed (a slow frame skips some).
    pub path_frame: u32,
    /// Seconds since the flight started.
    pub at_s: f64,
    /// The manager's decisions and requests, milliseconds.
    pub plan_ms: f64,
    /// Whether the frame was stale (see `Counters::stale_frames`).
    pub stale: bool,
    /// The factor the server's load put on the tolerance ([`Manager::load_scale`]).
    pub load_scale: f32,
    /// The server's load as last heard ([`Manager::server_wait`]), ms.
    pub server_wait_ms: f64,
    /// Textures asked for in the frame, for now and ahead.
    pub requests: u64,
    /// Whether an object of it had no texture that could be warped to the eye (stale as
    /// [`StaleCauses::missing`](crate::manager::StaleCauses::missing)).
    pub missing: bool,
    /// Final textures taken in for it.
    pub arrived: u32,
    /// Their round trips (request sent to arrival) summed, ms.
    pub arrivals_ms_sum: f64,
}

/// What a flight measured.
#[derive(Debug, Clone, Default)]
pub struct FlightLog {
    /// Frames flown (the manager decided each; path frames a slow one skipped are not).
    pub frames: u32,
    /// Per frame flown: what the manager did and heard, and the time it took.
    pub records: Vec<FrameRecord>,
    /// Per frame drawn: decisions and drawing together, milliseconds.
    pub frame_ms: Vec<f64>,
    /// The path's orbits around an object that may be an impostor, and the textures of
    /// it that arrived while the flight was on them.
    pub orbits: Vec<OrbitLog>,
}

/// An orbit segment of the path around an object, and what it cost.
#[derive(Debug, Clone)]
pub struct OrbitLog {
    /// The object orbited.
    pub object: usize,
    pub name: String,
    /// The segment's path frames and turns.
    pub frames: std::ops::Range<u32>,
    pub turns: f64,
    /// Final textures of the object received before the flight reached the orbit, and
    /// by the last frame it showed of it; `None` while the flight never reached it.
    received_before: Option<u64>,
    received: u64,
    /// The last path frame shown on the orbit.
    last_frame: u32,
}

impl FlightLog {
    /// New textures received per full turn for each object orbited, over the part of
    /// each orbit flown.
    pub fn regenerations_per_orbit(&self) -> BTreeMap<String, f64> {
        self.orbits
            .iter()
            .filter_map(|orbit| {
                let before = orbit.received_before?;
                let flown = (orbit.last_frame + 1 - orbit.frames.start) as f64 / orbit.frames.len() as f64;
                let count = orbit.received - before;
                Some((orbit.name.clone(), count as f64 / (orbit.turns.max(1e-3) * flown)))
            })
            .collect()
    }
}

impl Flight<'_> {
    /// The camera at `position` path frames into the flight; `None` for a scene without
    /// a camera path.
    pub fn camera_at(&self, position: f64) -> Option<Result<Camera, CameraError>> {
        let path = &self.scene.path;
        let mut frame = position + self.start as f64;
        if self.wrap {
            frame %= path.frame_count().max(1) as f64;
        }
        let pose = path.pose_at(frame)?;
        Some(pose.camera(self.scene.fov_y_degrees, self.size.0, self.size.1))
    }

    /// Before the flight: asks for the textures of its first frame and of its views
    /// [`WARM_UP_AHEAD_S`] seconds in (those the flight reaches), and waits (at most
    /// [`WARM_UP_LIMIT`]) until they are there. Whether they all arrived; `true`
    /// without a path. An error only where the first frame's camera is one.
    pub fn warm_up(&self, manager: &mut Manager) -> Result<bool, CameraError> {
        let Some(first) = self.camera_at(0.0) else {
            return Ok(true);
        };
        let ahead = (WARM_UP_AHEAD_S.iter())
            .map(|s| s * self.fps as f64)
            .take_while(|&position| position < self.frames as f64)
            .filter_map(|position| self.camera_at(position)?.ok());
        let cameras: Vec<Camera> = std::iter::once(first?).chain(ahead).collect();
        Ok(manager.warm_up(self.scene, &cameras, WARM_UP_LIMIT))
    }

    /// Flies the path: each frame the manager decides (and asks for textures), frames
    /// for which `draw(index)` holds are drawn, and `each` sees every frame flown; it
    /// may end the flight early ([`ControlFlow::Break`]) or fail it. Time `each` takes
    /// is the flight's: the eye moves on meanwhile.
    pub fn fly<E: From<CameraError>>(
        &self,
        manager: &mut Manager,
        draw: impl Fn(u32) -> bool,
        mut each: impl FnMut(Flown) -> Result<ControlFlow<()>, E>,
    ) -> Result<FlightLog, E> {
        let scene = self.scene;
        let mut log = FlightLog {
            orbits: self.orbits(),
            ..FlightLog::default()
        };
        let mut gbuffer = GBuffer::new(self.size.0, self.size.1);
        for (t, position) in FlightClock::start(self.fps, self.frames) {
            let Some(camera) = self.camera_at(position) else {
                break;
            };
            let camera = camera?;
            let path_frame = position as u32 + self.start;
            for orbit in &mut log.orbits {
                if orbit.frames.contains(&path_frame) {
                    let received = manager.received(orbit.object);
                    orbit.received_before.get_or_insert(received);
                    orbit.received = received;
                    orbit.last_frame = path_frame;
                }
            }
            let began = Instant::now();
            let asked = |m: &Manager| m.counters.requests_now + m.counters.requests_predicted;
            let (stale_before, asked_before) = (manager.counters.stale_frames, asked(manager));
            let (missing_before, arrived_before) = (
                manager.counters.stale_causes.missing,
                manager.counters.latencies_ms.len(),
            );
            let shows = manager.frame(scene, &camera, t);
            // (Counters only grow in a flight — a warm-up starts them again — so this
            // is the frame's arrivals.)
            let arrivals = || manager.counters.latencies_ms.get(arrived_before..).unwrap_or(&[]);
            log.records.push(FrameRecord {
                path_frame,
                at_s: t,
                plan_ms: began.elapsed().as_secs_f64() * 1e3,
                stale: manager.counters.stale_frames > stale_before,
                load_scale: manager.load_scale(),
                server_wait_ms: manager.server_wait().as_secs_f64() * 1e3,
                requests: asked(manager) - asked_before,
                missing: manager.counters.stale_causes.missing > missing_before,
                arrived: arrivals().len() as u32,
                arrivals_ms_sum: arrivals().iter().sum(),
            });
            let image = draw(log.frames).then(|| {
                let image = manager.render(scene, &shows, &camera, &mut gbuffer);
                log.frame_ms.push(began.elapsed().as_secs_f64() * 1e3);
                image
            });
            let shown = shows
                .iter()
                .enumerate()
                .map(|(k, show)| manager.describe(scene, k, show, &camera))
                .collect();
            let flown = Flown {
                index: log.frames,
                path_frame,
                t,
                camera: &camera,
                image,
                shown,
            };
            log.frames += 1;
            if each(flown)?.is_break() {
                break;
            }
        }
        Ok(log)
    }

    /// The path's orbit segments around objects that may be impostors.
    fn orbits(&self) -> Vec<OrbitLog> {
        let scene = self.scene;
        let mut orbits = Vec::new();
        let mut first = 0u32;
        for segment in &scene.path.segments {
            let n = segment.frames();
            if let PathSegment::Orbit { center, turns, .. } = segment
                && let Some(object) = orbited(scene, DVec3::from_array(*center))
            {
                orbits.push(OrbitLog {
                    object,
                    name: scene.objects[object].name.clone(),
                    frames: first..first + n,
                    turns: *turns,
                    received_before: None,
                    received: 0,
                    last_frame: first,
                });
            }
            first += n;
        }
        orbits
    }
}

/// The object an orbit about `center` circles: one that may be an impostor, whose
/// bounds hold the centre.
fn orbited(scene: &Scene, center: DVec3) -> Option<usize> {
    scene
        .objects
        .iter()
        .position(|o| o.local_bounds.expanded(1e-3).contains(o.to_local(center)) && !is_cheap(o))
}
