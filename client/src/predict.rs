//! The viewpoint predictor: where will the eye be `dt` from now, and where will it look?
//!
//! A least-squares quadratic fit (position, velocity, acceleration) to the last few eye
//! samples since the last corner the eye turned, each axis on its own, read at the
//! samples' mean time (where a quadratic fit's slope and curvature are truest) and
//! extrapolated as a steady turn: the velocity turning at the rate the acceleration
//! across it turns it, the speed changing as the acceleration along it changes it.
//! Straight paths, at a steady speed or a steady change of speed, are predicted
//! exactly, and orbits closely (the fit's bias: a centimetre a second ahead). The view
//! turns on at the mean rate it turned over the same samples.
//!
//! (Extrapolated as the quadratic itself, an orbit of the default demo was off by
//! 0.49 m a second ahead, half the time; as a turn, by 4 mm. On its straight legs the
//! two are the same.)

use std::collections::VecDeque;

use glam::{DVec3, Quat, Vec3};

use relief_core::camera::Camera;

/// How many recent samples the fit uses.
const WINDOW: usize = 8;

/// A step this many times longer than the last one's speed allows (plus
/// [`CUT_MIN_STEP`] metres, so an eye starting from rest is not a cut) is a camera cut.
const CUT_SPEED_RATIO: f64 = 4.0;
const CUT_MIN_STEP: f64 = 0.5;

/// A step whose direction turns by more than this (radians) from the step before, at
/// more than [`CORNER_TURN_RATE`], is a corner: the eye's motion before it says nothing
/// of its motion after, and a fit across it extrapolates the turn. The history starts
/// again from the sample before the turning step. (The forest's flight turns 90–140° at
/// its corners: fitted across them, the eye 0.5 s ahead was off by 3.4 m or more one
/// time in ten, and by up to 16 m; from the corner on, 1.9 m and 7.2 m. The view's
/// history goes too, so that for a few frames its turn is hardly foreseen: kept whole,
/// it asked the forest at rtt 100 for more textures ahead, 1,542–1,636 against
/// 1,523–1,589, and went stale in 20–53 frames of about 515 against 17–30, six runs
/// each, alternately.)
const CORNER_TURN: f64 = 20.0 * std::f64::consts::PI / 180.0;

/// … radians a second: a curve the eye follows smoothly turns each step by its rate
/// times the step's time, which a slow frame (the eye follows the clock) makes long —
/// an orbit of 240 frames turns 45° a second, 20° in a frame of 0.44 s.
const CORNER_TURN_RATE: f64 = std::f64::consts::PI;

/// A turn (radians, from the samples' mean time to the time predicted) below which the
/// eye is foreseen along the fitted quadratic: the two differ by about `MIN_TURN²/6` of
/// the way gone, and the turn's terms lose precision as it vanishes.
const MIN_TURN: f64 = 1e-3;

/// The farthest the view is foreseen to turn, radians: a turn kept up much longer
/// than the samples it was measured over means little.
pub const MAX_VIEW_TURN: f32 = std::f32::consts::FRAC_PI_2;

/// … and for no longer than this many times the span of the samples it was measured
/// over. (Under load a round trip, and with it the horizon, runs to seconds: turned on
/// for all of it, the view asked 40–85 % more textures of 64 clients and stalled them
/// more. For the samples' span alone, 0.23 s at 30 frames a second, it fell short of
/// the default demo's corners at rtt 100, where the horizon is 0.27 s.)
pub const VIEW_TURN_SPANS: f64 = 2.0;

/// Recent eye positions in the world (as [`Camera::eye`]) and the view's orientation
/// (the rotation taking x, y, −z to the camera's right, up and forward), with their
/// times (seconds).
#[derive(Debug, Clone, Default)]
pub struct Predictor {
    samples: VecDeque<(f64, DVec3, Quat)>,
}

/// The orientation of `camera`'s view: the rotation taking x, y and −z to its right,
/// up and forward.
pub fn view_of(camera: &Camera) -> Quat {
    Quat::from_mat3(&glam::Mat3::from_cols(camera.right, camera.up, -camera.forward)).normalize()
}

impl Predictor {
    /// Records the eye and its `view` ([`view_of`]) at time `t` (seconds, increasing).
    /// A jump far faster than the eye has been moving (a camera cut) starts the history
    /// afresh: a fit across it would extrapolate the jump. A corner (see `CORNER_TURN`)
    /// starts it afresh from the sample before the turning step.
    pub fn observe(&mut self, t: f64, eye: DVec3, view: Quat) {
        let Some(&(last_t, last, _)) = self.samples.back() else {
            self.samples.push_back((t, eye, view));
            return;
        };
        if t <= last_t {
            return;
        }
        if let Some(&(before_t, before, _)) = self.samples.iter().rev().nth(1) {
            let speed = last.distance(before) / (last_t - before_t);
            let step = eye.distance(last);
            if step > CUT_SPEED_RATIO * speed * (t - last_t) + CUT_MIN_STEP {
                self.samples.clear();
            } else if is_corner(last - before, eye - last, t - last_t) {
                self.samples.drain(..self.samples.len() - 1);
            }
        }
        if self.samples.len() == WINDOW {
            self.samples.pop_front();
        }
        self.samples.push_back((t, eye, view));
    }

    /// The eye expected `dt` seconds after the last sample.
    pub fn predict(&self, dt: f64) -> Option<DVec3> {
        Some(self.motion()?.at(dt))
    }

    /// The motion fitted to the recent eyes, to be asked where the eye will be at any
    /// number of times (the fit is made once).
    pub fn motion(&self) -> Option<Motion> {
        let &(t_last, last, view_last) = self.samples.back()?;
        let n = self.samples.len();
        // The view's mean rate of turn over the samples (radians a second, about the
        // vector's axis).
        let &(t_first, _, view_first) = self.samples.front()?;
        let view_rate = if t_last > t_first {
            let (axis, angle) = (view_last * view_first.inverse()).to_axis_angle();
            let angle = if angle > std::f32::consts::PI {
                angle - std::f32::consts::TAU
            } else {
                angle
            };
            axis * (angle / (t_last - t_first) as f32)
        } else {
            Vec3::ZERO
        };
        // (With one sample, the eye stays.)
        let coefficients = if n < 2 { [[0.0; 3]; 3] } else { fit(&self.samples)? };
        // The fit read at the samples' mean time, `mid` before the last.
        let mid = self.samples.iter().map(|&(t, _, _)| t - t_last).sum::<f64>() / n as f64;
        let at_mid = |derivative: usize| {
            DVec3::from_array(coefficients.map(|[c0, c1, c2]| match derivative {
                0 => c0 + c1 * mid + c2 * mid * mid,
                1 => c1 + 2.0 * c2 * mid,
                _ => 2.0 * c2,
            }))
        };
        Some(Motion {
            last,
            mid,
            offset: at_mid(0),
            velocity: at_mid(1),
            acceleration: at_mid(2),
            view_rate,
            view_span: t_last - t_first,
        })
    }
}

/// Per axis, `x(τ) = c0 + c1·τ + c2·τ²` fitted to `samples` (at least two) by least
/// squares, `τ` relative to the last sample and `x` to its position (an eye far from
/// the origin is fitted as precisely); with fewer than three samples, a line. `None`
/// where the fit is singular.
fn fit(samples: &VecDeque<(f64, DVec3, Quat)>) -> Option<[[f64; 3]; 3]> {
    let &(t_last, last, _) = samples.back()?;
    let degree = if samples.len() >= 3 { 2 } else { 1 };
    let mut ata = [[0f64; 3]; 3];
    let mut atb = [[0f64; 3]; 3];
    for &(t, p, _) in samples {
        let tau = t - t_last;
        let basis = [1.0, tau, tau * tau];
        for r in 0..=degree {
            for c in 0..=degree {
                ata[r][c] += basis[r] * basis[c];
            }
            for axis in 0..3 {
                atb[axis][r] += basis[r] * (p[axis] - last[axis]);
            }
        }
    }
    let mut coefficients = [[0f64; 3]; 3];
    for axis in 0..3 {
        coefficients[axis] = solve(&ata, &atb[axis], degree + 1)?;
    }
    Some(coefficients)
}

/// The eye's motion as [`Predictor::motion`] fitted it, at the samples' mean time: its
/// position (from the last eye), velocity and acceleration, to be turned on from
/// there; and the view's rate of turn.
#[derive(Debug, Clone, Copy)]
pub struct Motion {
    last: DVec3,
    /// The samples' mean time, seconds after the last (so at most 0).
    mid: f64,
    /// The eye then, from `last`.
    offset: DVec3,
    velocity: DVec3,
    acceleration: DVec3,
    /// The view's rate of turn: radians a second about the vector's direction, in the
    /// world.
    view_rate: Vec3,
    /// The seconds the samples span: the view is foreseen to turn on no longer.
    view_span: f64,
}

impl Motion {
    /// The eye expected `dt` seconds after the last sample, turning on as it turned
    /// (see the [module](self)): its velocity turned at the rate `ω` the acceleration
    /// across it turns it, about the axis it turns it about, its speed changed at the
    /// rate `α` the acceleration along it changes it. Where it hardly turns, or turns
    /// faster than a curve is followed (`CORNER_TURN_RATE`: a turn that tight is a
    /// corner the history will start again from), the fitted quadratic.
    /// (That sample's eye where neither gives a finite position.)
    pub fn at(&self, dt: f64) -> DVec3 {
        let t = dt - self.mid;
        let speed = self.velocity.length();
        let along = self.velocity / speed;
        let alpha = self.acceleration.dot(along);
        let across = self.acceleration - alpha * along;
        let omega = across.length() / speed;
        let offset = if (omega * t).abs() > MIN_TURN && omega <= CORNER_TURN_RATE {
            // ∫₀ᵗ (s + α u)(cos ωu · along + sin ωu · side) du
            let side = across / across.length();
            let (sin, cos) = (omega * t).sin_cos();
            let forward = speed * sin / omega + alpha * ((cos - 1.0) / (omega * omega) + t * sin / omega);
            let sideways = speed * (1.0 - cos) / omega + alpha * (sin / (omega * omega) - t * cos / omega);
            forward * along + sideways * side
        } else {
            self.velocity * t + 0.5 * self.acceleration * t * t
        };
        let eye = self.last + self.offset + offset;
        if eye.is_finite() { eye } else { self.last }
    }

    /// How far (radians) the view will have turned `dt` seconds after the last sample,
    /// as [`Motion::camera_at`] turns it: at its rate for no longer than
    /// [`VIEW_TURN_SPANS`] times the samples' span, and by [`MAX_VIEW_TURN`] at most.
    pub fn view_turn(&self, dt: f64) -> f32 {
        self.view_turn_vector(dt).length()
    }

    /// The view's turn `dt` seconds after the last sample (radians about the vector's
    /// direction): at its rate for no longer than [`VIEW_TURN_SPANS`] times the samples'
    /// span, and by [`MAX_VIEW_TURN`] at most.
    fn view_turn_vector(&self, dt: f64) -> Vec3 {
        let turn = self.view_rate * dt.min(VIEW_TURN_SPANS * self.view_span) as f32;
        if turn.is_finite() {
            turn.clamp_length_max(MAX_VIEW_TURN)
        } else {
            Vec3::ZERO
        }
    }

    /// `camera` (in the world) as it will look `dt` seconds after the last sample: from
    /// the eye then ([`Motion::at`]), its view turned on at the rate it has been turning
    /// ([`Motion::view_turn`]).
    pub fn camera_at(&self, dt: f64, camera: &Camera) -> Camera {
        let rotation = Quat::from_scaled_axis(self.view_turn_vector(dt));
        Camera {
            eye: self.at(dt),
            forward: (rotation * camera.forward).normalize(),
            right: (rotation * camera.right).normalize(),
            up: (rotation * camera.up).normalize(),
            ..*camera
        }
    }
}

/// Whether a step of the eye along `next`, taking `dt` seconds, after one along
/// `before` turns a corner ([`CORNER_TURN`], [`CORNER_TURN_RATE`]). A still eye turns
/// none.
fn is_corner(before: DVec3, next: DVec3, dt: f64) -> bool {
    let lengths = before.length() * next.length();
    // (A zero step has no direction: no corner.)
    let turn = (before.dot(next) / lengths).clamp(-1.0, 1.0).acos();
    lengths > 0.0 && turn > CORNER_TURN && turn > CORNER_TURN_RATE * dt
}

/// Solves the `n × n` leading block of `a·x = b` by Gaussian elimination with partial
/// pivoting; `None` when singular.
fn solve(a: &[[f64; 3]; 3], b: &[f64; 3], n: usize) -> Option<[f64; 3]> {
    let mut m = [[0f64; 4]; 3];
    for r in 0..n {
        m[r][..n].copy_from_slice(&a[r][..n]);
        m[r][3] = b[r];
    }
    for col in 0..n {
        let pivot = (col..n).max_by(|&x, &y| m[x][col].abs().total_cmp(&m[y][col].abs()))?;
        if m[pivot][col].abs() < 1e-12 {
            return None;
        }
        m.swap(col, pivot);
        let pivot_row = m[col];
        for (r, row) in m.iter_mut().enumerate().take(n) {
            if r != col {
                let factor = row[col] / pivot_row[col];
                for (value, p) in row.iter_mut().zip(pivot_row).skip(col) {
                    *value -= factor * p;
                }
            }
        }
    }
    let mut x = [0f64; 3];
    for r in 0..n {
        x[r] = m[r][3] / m[r][r];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A straight path, at a steady speed or speeding up steadily, is foreseen exactly.
    #[test]
    fn straight_paths_are_exact() {
        for (speed, speed_up) in [(2.0, 0.0), (2.0, 3.0), (0.0, 1.5)] {
            let direction = DVec3::new(1.0, 0.5, -2.0).normalize();
            let at = |t: f64| DVec3::new(1.0, 3.0, 1e6) + direction * (speed * t + 0.5 * speed_up * t * t);
            let mut p = Predictor::default();
            for k in 0..6 {
                let t = k as f64 * 0.1;
                p.observe(t, at(t), Quat::IDENTITY);
            }
            let ahead = p.predict(0.5).unwrap();
            assert!(ahead.abs_diff_eq(at(1.0), 1e-6), "{ahead} against {}", at(1.0));
        }
    }

    /// An orbit is foreseen round the orbit, as far ahead as predictions look; a
    /// quadratic fitted to the same samples strays from it (the brute force).
    #[test]
    fn an_orbit_is_followed_round() {
        // The default demo's orbit: 4.5 m round, a turn in 8 s, the eye 0.8 m up.
        let rate = std::f64::consts::TAU / 8.0;
        let at = |t: f64| DVec3::new(3.0 + 4.5 * (rate * t).cos(), 2.1, 4.5 * (rate * t).sin());
        let mut p = Predictor::default();
        let last = 7.0 / 30.0;
        for k in 0..8 {
            let t = k as f64 / 30.0;
            p.observe(t, at(t), Quat::IDENTITY);
        }
        let motion = p.motion().unwrap();
        // (Within a centimetre for a second, 3 cm over 135° of the orbit.)
        for (dt, within) in [(0.1, 0.01), (0.5, 0.01), (1.0, 0.01), (3.0, 0.03)] {
            let error = motion.at(dt).distance(at(last + dt));
            assert!(error < within, "{dt} s ahead: off by {error} m");
        }
        // The quadratic through the samples, read from their own derivatives at
        // their mean time, 1 s ahead: off by decimetres.
        let t = 1.0 - motion.mid;
        let quadratic = motion.last + motion.offset + motion.velocity * t + 0.5 * motion.acceleration * t * t;
        assert!(quadratic.distance(at(last + 1.0)) > 0.3);
        assert!(Predictor::default().predict(1.0).is_none());
    }

    #[test]
    fn a_camera_cut_starts_the_fit_afresh() {
        let mut p = Predictor::default();
        for k in 0..8 {
            p.observe(
                k as f64 * 0.03,
                DVec3::new(k as f64 * 0.1, 0.0, 0.0),
                Quat::IDENTITY,
            );
        }
        // A cut 9 m away, then the eye still there a frame later.
        p.observe(0.24, DVec3::new(0.0, 0.0, 9.0), Quat::IDENTITY);
        p.observe(0.27, DVec3::new(0.0, 0.0, 9.0), Quat::IDENTITY);
        let ahead = p.predict(0.3).unwrap();
        assert!(ahead.distance(DVec3::new(0.0, 0.0, 9.0)) < 1e-3, "{ahead}");
        // Speeding up smoothly, by up to 2.3 m a frame, is not a cut.
        let mut p = Predictor::default();
        for k in 0..8 {
            let t = k as f64 * 0.03;
            p.observe(t, DVec3::new(200.0 * t * t, 0.0, 0.0), Quat::IDENTITY);
        }
        assert_eq!(p.samples.len(), WINDOW);
    }

    /// An eye turning a corner is foreseen going on along the new leg, not round the
    /// curve a fit across the corner makes of it; an orbit is no corner.
    #[test]
    fn a_corner_starts_the_fit_from_the_corner() {
        let mut p = Predictor::default();
        // 0.3 m a frame along +x, then a right-angle turn to +z.
        let leg = |k: u32| match k {
            0..=7 => DVec3::new(0.3 * k as f64, 0.0, 0.0),
            _ => DVec3::new(2.1, 0.0, 0.3 * (k - 7) as f64),
        };
        for k in 0..=9 {
            p.observe(k as f64 / 30.0, leg(k), Quat::IDENTITY);
        }
        let ahead = p.predict(0.5).unwrap();
        assert!(ahead.distance(leg(24)) < 1e-3, "{ahead} against {}", leg(24));
        // (Fitted across the corner, it was off by metres.)
        assert_eq!(p.samples.len(), 3);
        // An orbit of 240 frames is no corner, even in frames of half a second.
        for frame_s in [1.0 / 30.0, 0.5] {
            let mut orbit = Predictor::default();
            for k in 0..8 {
                let t = k as f64 * frame_s;
                let angle = t * 30.0 * std::f64::consts::TAU / 240.0;
                orbit.observe(t, DVec3::new(angle.cos(), 0.0, angle.sin()) * 4.5, Quat::IDENTITY);
            }
            assert_eq!(orbit.samples.len(), WINDOW, "frames of {frame_s} s");
        }
        // Nor is an eye that stops, or starts again.
        assert!(!is_corner(DVec3::X, DVec3::ZERO, 0.1) && !is_corner(DVec3::ZERO, DVec3::X, 0.1));
    }

    /// A view turning steadily about the vertical is foreseen turned on at its rate, for
    /// [`VIEW_TURN_SPANS`] times the samples' span at most, and by [`MAX_VIEW_TURN`] at
    /// most; the eye's prediction is not changed by it.
    #[test]
    fn a_turning_view_is_foreseen_turned_on() {
        let camera_at = |t: f64, rate: f32| {
            let yaw = t as f32 * rate;
            let target = Vec3::new(yaw.sin(), 0.0, -yaw.cos());
            Camera::look_at(Vec3::ZERO, target, Vec3::Y, 60.0, 320, 180).unwrap()
        };
        let motion = |rate: f32| {
            let mut p = Predictor::default();
            for k in 0..8 {
                let t = k as f64 / 30.0;
                p.observe(t, DVec3::ZERO, view_of(&camera_at(t, rate)));
            }
            p.motion().unwrap()
        };
        // One radian a second, over samples spanning 7/30 s.
        let (slow, last, span) = (motion(1.0), 7.0 / 30.0, 7.0 / 30.0);
        let ahead = slow.camera_at(0.2, &camera_at(last, 1.0));
        let expected = camera_at(last + 0.2, 1.0);
        assert!(ahead.forward.angle_between(expected.forward) < 1e-3, "{ahead:?}");
        assert!(ahead.up.angle_between(Vec3::Y) < 1e-3);
        assert_eq!(ahead.eye, DVec3::ZERO);
        assert!((slow.view_turn(0.2) - 0.2).abs() < 1e-3);
        assert!((slow.view_turn(10.0) - (VIEW_TURN_SPANS * span) as f32).abs() < 1e-3);
        // Ten radians a second: by the cap.
        let fast = motion(10.0);
        assert!((fast.view_turn(0.2) - MAX_VIEW_TURN).abs() < 1e-4);
        let far = fast.camera_at(0.2, &camera_at(last, 10.0));
        let turned = far.forward.angle_between(camera_at(last, 10.0).forward);
        assert!((turned - MAX_VIEW_TURN).abs() < 1e-3, "{turned}");
    }
}
