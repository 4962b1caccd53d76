//! Asking for textures: for now when an object has no valid one, and — predicted from
//! the eye's motion — ahead of need, early enough to cover the measured round trip;
//! withdrawing predictions the motion has left behind.

use std::time::Instant;

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::relief::SourceProjection;
use relief_core::scene::{Scene, SceneObject};
use relief_core::stats::percentile;
use relief_proto::limits::MAX_SERVE_WITHIN;
use relief_render::geometry::{GeometryReason, geometry_reason};

use crate::predict::Motion;

use super::Manager;
use super::around::angle_between;
use super::choose::{Grade, held_covering, held_partners, probe_lone_reach};
use super::messages::{Command, TextureRequest};
use super::policy::{
    GLIMPSE_LATENCY_PERCENTILE, HORIZON_FALLBACK_STEPS, HORIZON_MARGIN_S, HORIZON_SPARE, LATENCY_PERCENTILE,
    LATENCY_WINDOW, LEAD, LEAD_DISTANCE_SLACK, LEAD_PATH_STEPS, MAX_HORIZON_S, MIN_LEAD, OWN_LATENCIES,
    PENDING_DISTANCE_SLACK, PENDING_REACH, PREDICTED_VIEW_MARGIN, REQUESTED_DEPTH_BITS, SERVE_REACH,
    TEXTURE_LADDER, WITHDRAW_REACH, asked_for, largest_edge, projection_for,
};

#[derive(Debug, Clone, Copy)]
pub(super) struct Pending {
    pub(super) object: usize,
    /// In the object's frame, as every eye the manager keeps.
    pub(super) eye: Vec3,
    pub(super) sent: Instant,
    /// When a predicted request's texture is needed; `None` for one needed now.
    pub(super) needed_at: Option<Instant>,
}

/// How urgently a texture serving some eye was asked for ([`Manager::pending_covers`]),
/// least first.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Asked {
    Not,
    Predicted,
    Now,
}

impl Pending {
    pub(super) fn predicted(&self) -> bool {
        self.needed_at.is_some()
    }
}

/// The smallest edge of the [`TEXTURE_LADDER`] that holds `need` texels, the largest
/// when `need` is beyond.
pub fn texture_ladder(need: u32) -> u32 {
    let largest = TEXTURE_LADDER[TEXTURE_LADDER.len() - 1];
    TEXTURE_LADDER
        .into_iter()
        .find(|&edge| edge >= need)
        .unwrap_or(largest)
}

/// How near another eye must be for its texture to serve a request at `eye` for an
/// object centred on `centre` with `valid_angle`, holding textures made for
/// `held_eyes`: as a fraction of `eye`'s distance from the centre, [`SERVE_REACH`] of
/// the valid angle, and less than half the way to any held texture's eye — so what
/// comes back is never a texture held already, which could not cover what the request
/// is for (and, cached, would answer every request again).
pub(super) fn serve_within(
    centre: Vec3,
    eye: Vec3,
    valid_angle: f32,
    held_eyes: impl Iterator<Item = Vec3>,
) -> f32 {
    let nearest_held = held_eyes.map(|h| h.distance(eye)).fold(f32::INFINITY, f32::min);
    let within = (SERVE_REACH * valid_angle)
        .min(0.5 * nearest_held / eye.distance(centre))
        .min(MAX_SERVE_WITHIN);
    if within.is_finite() && within > 0.0 {
        within
    } else {
        0.0
    }
}

/// The eye to make a predicted texture for, of an object centred on `centre`: the eye
/// further along its predicted path (`beyond`, after `future`) where it has turned
/// about `centre` by `angle` past `future` (the path's last eye if it turns less;
/// `future` itself where the eye does not turn: `turn`, radians from now to `future`).
/// The texture is then first used `angle` behind its own eye and stays in use as far
/// ahead: it serves twice the lead of the motion, where one made for the future eye
/// would serve the lead alone
/// ([`Manager::lead_angle`] says how far a texture may be seen from). It stops short
/// where the path's distance from the centre leaves [`LEAD_DISTANCE_SLACK`] of
/// `future`'s.
///
/// Along the path, not turned on about the centre: an eye passing close by an object
/// turns about it in a plane tilted by the pass, and turned on in that plane it can
/// land where no eye on the path goes (under the object) — a texture no eye could use,
/// which as a pending request would still hold the next prediction back. (Between two
/// path eyes the lead is on the chord: on a path curving by tens of degrees between
/// them it could dip under the distance slack, which the path's spacing keeps far off.)
pub(super) fn lead(centre: Vec3, angle: f32, turn: f32, future: Vec3, beyond: &[Vec3]) -> Vec3 {
    if turn.is_nan() || turn <= MIN_LEAD || angle <= MIN_LEAD {
        return future;
    }
    let mut previous = (future, 0.0);
    let distance = (future - centre).length();
    for &eye in beyond {
        let turn = angle_between(centre, future, eye);
        let ratio = (eye - centre).length() / distance;
        if turn.is_nan() || (ratio - 1.0).abs() >= LEAD_DISTANCE_SLACK {
            break;
        }
        if turn >= angle {
            // (Between two path eyes, in proportion to the turn.)
            let (p, p_turn) = previous;
            return p + (eye - p) * ((angle - p_turn) / (turn - p_turn)).clamp(0.0, 1.0);
        }
        previous = (eye, turn);
    }
    previous.0
}

/// The eye's path past the `horizon` ahead, as [`lead`] walks it: [`LEAD_PATH_STEPS`]
/// eyes evenly spaced over the `span` seconds after it, in `object`'s frame (fewer: it
/// stops before an eye drawn as geometry, too near). Worked out only when a prediction
/// is asked for, not every frame.
fn path_beyond(object: &SceneObject, motion: &Motion, horizon: f64, span: f64) -> Vec<Vec3> {
    (1..=LEAD_PATH_STEPS)
        .map(|step| motion.at(horizon + span * step as f64 / LEAD_PATH_STEPS as f64))
        .take_while(|&eye| geometry_reason(object, eye) != Some(GeometryReason::TooNear))
        .map(|eye| object.to_local(eye))
        .collect()
}

/// What [`Manager::predict_for`] decides from ([`Manager::prediction`]).
pub(super) struct Prediction {
    /// Seconds ahead the eye is planned for.
    horizon: f64,
    /// The eye's motion as fitted, to follow its path past `future` ([`path_beyond`]).
    motion: Motion,
    /// The eye then, in the object's frame.
    future: Vec3,
    /// Each held texture's eye and its grade from `future`; `None` where a view from
    /// there, turned as now or by up to [`PREDICTED_VIEW_MARGIN`] further (or as the
    /// view is foreseen to turn, past that margin), would not show the object: nothing
    /// is asked for it, and what was is withdrawn.
    held: Option<Vec<(Vec3, Grade)>>,
}

impl Manager {
    /// Records the round trip of `pending`, whose final texture reached the client at
    /// `arrived` and is taken in now: in the counters (latency to its arrival, and the
    /// pick-up from there to now), and in the windows the round trip to plan for is
    /// taken from (to now: when the texture can be used).
    pub(super) fn record_round_trip(&mut self, pending: &Pending, arrived: Instant) {
        let ms_between = |from: Instant, to: Instant| to.saturating_duration_since(from).as_secs_f64() * 1e3;
        let now = Instant::now();
        let latency = ms_between(pending.sent, arrived);
        self.counters.latencies_ms.push(latency);
        match pending.needed_at {
            None => self.counters.latencies_now_ms.push(latency),
            // (Signed: early is negative.)
            Some(needed) => self
                .counters
                .prediction_lateness_ms
                .push(ms_between(needed, arrived) - ms_between(arrived, needed)),
        }
        self.counters.pickup_ms.push(ms_between(arrived, now));
        let ms = ms_between(pending.sent, now);
        tracing::debug!(
            object = pending.object,
            ms,
            predicted = pending.predicted(),
            "round trip"
        );
        for recent in [
            &mut self.recent_latencies,
            &mut self.objects[pending.object].recent_latencies,
        ] {
            recent.push(ms / 1e3);
            if recent.len() > LATENCY_WINDOW {
                recent.remove(0);
            }
        }
    }

    /// The round trip to plan for: the [`LATENCY_PERCENTILE`] of the recent ones (the
    /// configured estimate before any). Round trips vary several-fold with the
    /// workers' queue; planning for a typical one would leave every slower one stalled.
    /// An object with [`OWN_LATENCIES`] round trips of its own plans for those: a heavy
    /// object takes longer to trace than the rest.
    pub(super) fn latency(&self, object: usize) -> f64 {
        self.latency_at(object, LATENCY_PERCENTILE)
    }

    /// The `wanted` percentile of the recent round trips [`Manager::latency`] plans
    /// from.
    fn latency_at(&self, object: usize, wanted: f64) -> f64 {
        let own = &self.objects[object].recent_latencies;
        let recent = if own.len() >= OWN_LATENCIES {
            own
        } else {
            &self.recent_latencies
        };
        if recent.is_empty() {
            return self.config.initial_latency;
        }
        percentile(recent, wanted)
    }

    /// How urgently a request already out for `object`, or for another placement of its
    /// mesh (whose texture it will share: see [`Manager::share`]), was asked for that
    /// will serve `eye`: the most urgent such one's, [`Asked::Not`] if none will.
    pub(super) fn pending_covers(&self, scene: &Scene, object: usize, centre: Vec3, eye: Vec3) -> Asked {
        let reach = PENDING_REACH * self.valid_angle(object);
        let mesh = &scene.objects[object];
        (self.pending.values())
            .filter(|p| {
                (p.object == object || scene.objects[p.object].shares_mesh(mesh))
                    && angle_between(centre, p.eye, eye) < reach
                    && ((p.eye - centre).length() / (eye - centre).length() - 1.0).abs()
                        < PENDING_DISTANCE_SLACK
            })
            .map(|p| {
                if p.predicted() {
                    Asked::Predicted
                } else {
                    Asked::Now
                }
            })
            .max()
            .unwrap_or(Asked::Not)
    }

    /// The texture to ask for from `eye`: its edge — what the screen can show of the
    /// object ([`asked_for`]), rounded up to the [`texture_ladder`], at most the
    /// projection's [`largest_edge`] — and its projection.
    pub(super) fn size_for(
        object: &SceneObject,
        eye: Vec3,
        camera: &Camera,
        in_perspective: bool,
    ) -> (u32, SourceProjection) {
        let (projection, edge) = asked_for(
            object,
            &Camera {
                eye: eye.as_dvec3(),
                ..*camera
            },
            in_perspective,
        );
        let edge = texture_ladder(edge.unwrap_or(u32::MAX)).min(largest_edge(object, projection));
        (edge, projection)
    }

    pub(super) fn request(
        &mut self,
        scene: &Scene,
        object: usize,
        eye: Vec3,
        camera: &Camera,
        needed_in_ms: Option<u64>,
    ) {
        let o = &scene.objects[object];
        let (size, projection) = Self::size_for(o, eye, camera, self.objects[object].in_perspective);
        let id = self.next_id;
        self.next_id += 1;
        let request = TextureRequest {
            id,
            object: o.name.clone(),
            eye,
            size,
            depth_bits: REQUESTED_DEPTH_BITS,
            projection,
            needed_in_ms,
            serve_within: serve_within(
                o.local_bounds.center(),
                eye,
                self.valid_angle(object),
                self.objects[object].held.iter().map(|h| h.eye),
            ),
        };
        if self.commands.send(Command::Request(request)).is_err() {
            return;
        }
        let sent = Instant::now();
        self.pending.insert(
            id,
            Pending {
                object,
                eye,
                sent,
                needed_at: needed_in_ms.map(|ms| sent + std::time::Duration::from_millis(ms)),
            },
        );
        match needed_in_ms {
            Some(_) => self.counters.requests_predicted += 1,
            None => self.counters.requests_now += 1,
        }
    }

    /// Where the eye will be once a request for object `k` made now comes back (in the
    /// object's frame, as `camera` is; `world_camera` is the same in the world) — or, for
    /// an object in view now that will not be shown by then, where it last will be
    /// (`HORIZON_FALLBACK_STEPS`) — and how each held texture grades there (none where
    /// the object will be out of view: see [`Prediction::held`]): what
    /// [`Manager::predict_for`] decides from. `None` where nothing is to be asked ahead:
    /// no eye observed yet, drawn as geometry from there, or in view now and not shown
    /// again once a texture could come (and never asked for where the frame does not
    /// predict: `Manager::plan`). It only reads, so a frame works it out for every
    /// object at once.
    pub(super) fn prediction(
        &self,
        scene: &Scene,
        k: usize,
        camera: &Camera,
        world_camera: &Camera,
    ) -> Option<Prediction> {
        // The round trip to plan for, with time to spare.
        let round_trip = self.latency(k);
        let horizon = (HORIZON_SPARE * round_trip + HORIZON_MARGIN_S).min(MAX_HORIZON_S);
        let motion = self.predictor.motion()?;
        let object = &scene.objects[k];
        let bounds = &object.local_bounds;
        // Shown as an impostor from `ahead` seconds on: not too near, and seen from there
        // looking as now (turned by up to the margin), or — where the view is turning
        // faster than the margin allows for (a corner of the path) — in the view as it
        // will then look. (With the margin round that view too, or every turn taken
        // into account, the forest's wandering flight asked a fifth more predictions
        // and went stale more.)
        let shown_at = |ahead: f64| {
            let eye = motion.at(ahead);
            if geometry_reason(object, eye) == Some(GeometryReason::TooNear) {
                return None;
            }
            let local = object.to_local(eye);
            let from_there = Camera {
                eye: local.as_dvec3(),
                ..*camera
            };
            let in_view = from_there.may_see_turned(bounds, PREDICTED_VIEW_MARGIN)
                || (motion.view_turn(ahead) > PREDICTED_VIEW_MARGIN
                    && object
                        .local_camera(&motion.camera_at(ahead, world_camera))
                        .may_see(bounds));
            Some(in_view)
        };
        // An object in view now that will be out of view, or too near, at the horizon
        // is still shown until then: planned for the last of the times between a
        // typical round trip and the horizon it is shown at. (Planned for the horizon
        // alone, an eye sweeping past the rock in a lossy flight saw it turned 90°
        // round unforeseen. Looked for whether in view now or not, the forest asked 10 %
        // more predictions and went stale more.)
        // Where it is not shown then either, nothing is asked, and what was asked is
        // kept: the predictions for its last glimpse are still coming (withdrawn, they
        // were lost once that glimpse came within the round trip).
        let (mut ahead, mut shown) = (horizon, shown_at(horizon));
        if shown != Some(true) && camera.may_see(bounds) {
            // (Needed that soon, such a request is often late — and the server puts it
            // before the predictions needed later.)
            let typical = self.latency_at(k, GLIMPSE_LATENCY_PERCENTILE);
            let sooner = (1..=HORIZON_FALLBACK_STEPS)
                .map(|step| horizon - (horizon - typical) * step as f64 / HORIZON_FALLBACK_STEPS as f64);
            (ahead, shown) = (typical < horizon)
                .then(|| sooner.map(|t| (t, shown_at(t))).find(|(_, s)| *s == Some(true)))
                .flatten()
                .unwrap_or((horizon, None));
        }
        // Drawn as geometry from there, or not shown again: nothing to ask for.
        let in_view = shown?;
        let future = object.to_local(motion.at(ahead));
        let held = if in_view {
            // (Asked for as soon as a texture would pay: `cheaper_as_geometry`.)
            let grades = self.grades(scene, k, future, camera)?;
            Some((self.objects[k].held.iter().map(|h| h.eye)).zip(grades).collect())
        } else {
            None
        };
        Some(Prediction {
            horizon: ahead,
            motion,
            future,
            held,
        })
    }

    /// Asks ahead for the texture the eye will need once a request for object `k`
    /// made now comes back, as `prediction` ([`Manager::prediction`]) foresees, and
    /// withdraws predictions the motion has left behind. `camera` in the object's
    /// frame.
    pub(super) fn predict_for(
        &mut self,
        scene: &Scene,
        k: usize,
        camera: &Camera,
        prediction: Option<Prediction>,
    ) {
        let Some(Prediction {
            horizon,
            motion,
            future,
            held,
        }) = prediction
        else {
            return;
        };
        let centre = scene.objects[k].local_bounds.center();
        let eye = camera.eye_f32();
        let Some(held) = held else {
            self.withdraw_predictions(k, |_| true);
            return;
        };
        let asked: Vec<Vec3> = (self.pending.values())
            .filter(|p| p.object == k)
            .map(|p| p.eye)
            .collect();
        let covering = held_covering(centre, future, &held, &asked, self.tolerance());
        let covered = covering.is_some() || self.pending_covers(scene, k, centre, future) != Asked::Not;
        let now = Instant::now();
        // What the plan counts on is kept (see `Held::relied_on`): the texture covering
        // the future, and any held that could partner it there. (`held` was graded this
        // frame, after the last arrivals: the same order.)
        if let Some(i) = covering {
            for j in std::iter::once(i).chain(held_partners(centre, held[i].0, future, &held)) {
                if let Some(h) = self.objects[k].held.get_mut(j) {
                    h.relied_on = now;
                }
            }
        }
        // (Quiet a while after the saturated server refused one: see `SHED_QUIET`.)
        let quiet = self.objects[k].quiet_until.is_some_and(|t| now < t);
        if !covered && !quiet {
            let lead_angle = self.lead_angle(k, &scene.objects[k], centre, eye, future, camera);
            // Time for the eye, turning as it has been, to turn the lead past the future
            // (the path known no further than `MAX_HORIZON_S` ahead).
            let turn = angle_between(centre, eye, future);
            let span =
                (horizon * f64::from(lead_angle / turn).max(1.0)).min((MAX_HORIZON_S - horizon).max(0.0));
            let beyond = path_beyond(&scene.objects[k], &motion, horizon, span);
            let ask = lead(centre, lead_angle, turn, future, &beyond);
            // While warming up, needed no sooner than the flight starts: taken for
            // needed a round trip from now, the predictions of the forest's first
            // view (40 of them, the objects round its edges) were refused by a server
            // busy with the cold start, and were missing as the flight set off.
            let needed_in = match self.warm_up_until {
                Some(until) => until.saturating_duration_since(now).as_secs_f64().max(horizon),
                None => horizon,
            };
            self.request(scene, k, ask, camera, Some((needed_in * 1e3) as u64));
        }
        // Predictions neither the eye nor its future will meet any more.
        let reach = WITHDRAW_REACH * self.valid_angle(k);
        self.withdraw_predictions(k, |p| {
            angle_between(centre, p.eye, eye) > reach && angle_between(centre, p.eye, future) > reach
        });
    }

    /// How far past the eye's `future` a predicted texture for object `k` is made
    /// ([`lead`]), the eye turning from `now` to `future` about `centre`: as far as the
    /// held texture nearest the future could be seen from behind its own eye and still
    /// be planned to be shown alone there, its gaps grown [`LEAD`] of the tolerance at
    /// most ([`probe_lone_reach`]: turned the way the eye moves, at the future's
    /// distance), so that the texture, first seen that far behind its eye, covers the
    /// future on its own. With none held, [`LEAD`] of the valid angle assumed. Never
    /// past [`PENDING_REACH`] of the valid angle: a request made farther would not count
    /// as covering the future, and the next frame would ask again. All in the object's
    /// frame.
    fn lead_angle(
        &self,
        k: usize,
        object: &SceneObject,
        centre: Vec3,
        now: Vec3,
        future: Vec3,
        camera: &Camera,
    ) -> f32 {
        let valid = self.valid_angle(k);
        let nearest = (self.objects[k].held.iter()).min_by(|a, b| {
            angle_between(centre, a.eye, future).total_cmp(&angle_between(centre, b.eye, future))
        });
        // (About the axis that turns the held texture's eye the way the eye moves.)
        let probed = nearest.and_then(|held| {
            let axis = (held.eye - centre).cross(future - now).normalize_or_zero();
            let distance = centre.distance(future);
            (axis != Vec3::ZERO).then(|| {
                // (The lone turn of the texture to be asked, not of the one held:
                // after a switch to perspective they differ.)
                let projection = projection_for(object, future, self.objects[k].in_perspective);
                probe_lone_reach(
                    held,
                    (object, projection),
                    centre,
                    axis,
                    distance,
                    camera,
                    self.tolerance(),
                )
            })
        });
        probed.unwrap_or(LEAD * valid).min(PENDING_REACH * valid)
    }

    /// Withdraws object `k`'s predicted requests that are `stale`.
    pub(super) fn withdraw_predictions(&mut self, k: usize, stale: impl Fn(&Pending) -> bool) {
        self.withdraw_predicted(|p| p.object == k && stale(p));
    }

    /// Withdraws the predicted requests, of any object, that are `stale`: one
    /// withdrawal sent for them all.
    pub(super) fn withdraw_predicted(&mut self, stale: impl Fn(&Pending) -> bool) {
        let stale: Vec<u64> = (self.pending.iter())
            .filter(|(_, p)| p.predicted() && stale(p))
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

    /// The reach is the valid angle's share, stops short of half the way to the
    /// nearest held texture's eye, is none at a held eye, and is at most the
    /// protocol's bound.
    #[test]
    fn the_reach_never_takes_in_a_held_texture() {
        let (centre, eye) = (Vec3::ZERO, Vec3::new(0.0, 0.0, 10.0));
        let valid = 0.2;
        let alone = serve_within(centre, eye, valid, std::iter::empty());
        assert_eq!(alone, SERVE_REACH * valid);
        let far = Vec3::new(5.0, 0.0, 10.0);
        assert_eq!(serve_within(centre, eye, valid, [far].into_iter()), alone);
        // A held eye 0.4 away: a reach of at most 0.2 (0.02 of the distance 10).
        let near = Vec3::new(0.4, 0.0, 10.0);
        let capped = serve_within(centre, eye, valid, [far, near].into_iter());
        assert!((capped - 0.02).abs() < 1e-6, "{capped}");
        assert!(capped * 10.0 < near.distance(eye));
        assert_eq!(serve_within(centre, eye, valid, [eye].into_iter()), 0.0);
        assert_eq!(
            serve_within(centre, eye, 10.0, std::iter::empty()),
            MAX_SERVE_WITHIN
        );
    }

    /// An eye flying a straight line past an object, 1 above its centre: the lead
    /// stays on the line, turned by the lead angle; it stops where the line recedes
    /// past the lead's distance slack, and is the future itself where the eye does not
    /// turn.
    #[test]
    fn a_lead_follows_the_eyes_path() {
        let centre = Vec3::ZERO;
        let on_line = |x: f32| Vec3::new(x, 1.0, 2.0);
        let (now, future) = (on_line(-2.0), on_line(0.0));
        let beyond: Vec<Vec3> = (1..=8).map(|k| on_line(k as f32 * 0.2)).collect();
        // (The line leaves the distance slack about 0.43 round.)
        let angle = 0.3;
        let turn = angle_between(centre, now, future);
        let eye = lead(centre, angle, turn, future, &beyond);
        assert!((eye.y - 1.0).abs() < 1e-6 && (eye.z - 2.0).abs() < 1e-6, "{eye}");
        let led = angle_between(centre, future, eye);
        assert!((led - angle).abs() < 1e-3, "{led}");
        // (Turned on about the centre instead, in the plane of the pass, it would sink
        // below the line.)
        let axis = (now - centre).cross(future - centre).normalize();
        let about_centre = centre + glam::Quat::from_axis_angle(axis, angle) * (future - centre);
        assert!(about_centre.y < 0.97, "{about_centre}");
        // Asked for more than the line turns within the slack: it stops inside it.
        let short = lead(centre, 0.6, turn, future, &beyond);
        let ratio = short.length() / future.length();
        assert!(
            ratio < 1.0 + LEAD_DISTANCE_SLACK && angle_between(centre, future, short) < 0.45,
            "{short}"
        );

        // A path receding fast: the lead stops within the pending slack.
        let receding: Vec<Vec3> = (1..=4)
            .map(|k| future * (1.0 + 0.15 * k as f32) + Vec3::X * 0.01 * k as f32)
            .collect();
        let eye = lead(centre, angle, turn, future, &receding);
        let ratio = eye.length() / future.length();
        assert!((ratio - 1.0).abs() < LEAD_DISTANCE_SLACK, "{ratio}");

        // No turn: the future.
        assert_eq!(lead(centre, angle, 0.0, future, &beyond), future);
    }
}
