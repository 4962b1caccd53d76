//! How long the link makes a round trip at best, and the factor that puts on the
//! tolerance.
//!
//! A texture must outlive the round trip of the one that replaces it, and the eye's
//! foreseen path is the less sure the further ahead it is asked for. The default
//! tolerance is tuned for a link of [`LINK_TUNED_ROUND_TRIP`] or less; over a longer
//! one its textures' lives were shorter than the round trips asking for them could
//! cover (the default demo at a 250 ms round trip: 5.0–8.0 % of frames stale at the
//! default tolerance, 0.7 % at twice it). So the tolerance grows with the shortest
//! round trip of the link's looks at the server's load lately
//! ([`Arrival::LinkRoundTrip`](super::Arrival::LinkRoundTrip)): the network's part,
//! which no bake or queue lengthens. (A texture's round trip is no measure of it: a
//! warm-up's, all objects asked for at once from workers still loading the scene, took
//! 140 ms at a 0 ms round trip. A busy server has a factor of its own: see
//! [`LOAD_HIGH_WAIT`](super::policy::LOAD_HIGH_WAIT).)

use std::time::Instant;

use super::policy::{LINK_TUNED_ROUND_TRIP, MAX_LOAD_SCALE, ROUND_TRIP_FLOOR_PERIOD};

/// The shortest round trip of the link's looks in the current period of
/// [`ROUND_TRIP_FLOOR_PERIOD`] and in the one before.
#[derive(Debug)]
pub(super) struct RoundTripFloor {
    /// Milliseconds, infinite where none came.
    floors: [f64; 2],
    /// When the current period began.
    period_start: Instant,
}

impl Default for RoundTripFloor {
    fn default() -> Self {
        RoundTripFloor {
            floors: [f64::INFINITY; 2],
            period_start: Instant::now(),
        }
    }
}

impl RoundTripFloor {
    /// Takes in a round trip of `ms`, ended at `now`.
    pub fn record(&mut self, ms: f64, now: Instant) {
        let periods = now.saturating_duration_since(self.period_start).as_secs_f64()
            / ROUND_TRIP_FLOOR_PERIOD.as_secs_f64();
        if periods >= 1.0 {
            // (Two periods or more without a look answered: nothing before counts.)
            let before = if periods < 2.0 {
                self.floors[0]
            } else {
                f64::INFINITY
            };
            self.floors = [f64::INFINITY, before];
            self.period_start = now;
        }
        self.floors[0] = self.floors[0].min(ms);
    }

    /// The shortest round trip of the last period or two, ms (infinite before any).
    pub fn ms(&self) -> f64 {
        self.floors[0].min(self.floors[1])
    }

    /// The factor the link puts on the tolerance: the floor over
    /// [`LINK_TUNED_ROUND_TRIP`], at least 1 (and 1 before any round trip), at most
    /// [`MAX_LOAD_SCALE`].
    pub fn scale(&self) -> f32 {
        let tuned = LINK_TUNED_ROUND_TRIP.as_secs_f64() * 1e3;
        let floor = self.ms();
        if !floor.is_finite() {
            return 1.0;
        }
        ((floor / tuned) as f32).clamp(1.0, MAX_LOAD_SCALE)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The floor is the shortest round trip; the factor is 1 up to the tuned round trip
    /// and grows in proportion past it, to its bound.
    #[test]
    fn the_factor_follows_the_shortest_round_trip() {
        let tuned = LINK_TUNED_ROUND_TRIP.as_secs_f64() * 1e3;
        let mut floor = RoundTripFloor::default();
        assert_eq!(floor.scale(), 1.0, "none yet");
        let now = Instant::now();
        for ms in [3.0 * tuned, 2.0 * tuned, 2.5 * tuned] {
            floor.record(ms, now);
        }
        assert_eq!(floor.ms(), 2.0 * tuned);
        assert!((floor.scale() - 2.0).abs() < 1e-6, "{}", floor.scale());
        floor.record(0.5 * tuned, now);
        assert_eq!(floor.scale(), 1.0, "under the tuned round trip");
        let mut far = RoundTripFloor::default();
        far.record(100.0 * tuned, now);
        assert_eq!(far.scale(), MAX_LOAD_SCALE);
    }

    /// Two periods without a look answered, the floor starts afresh.
    #[test]
    fn a_silence_of_two_periods_forgets_the_floor() {
        let mut floor = RoundTripFloor::default();
        let start = Instant::now();
        floor.record(10.0, start);
        floor.record(300.0, start + ROUND_TRIP_FLOOR_PERIOD * 3);
        assert_eq!(floor.ms(), 300.0);
    }

    /// The floor forgets round trips two periods old: a link that shortened for good
    /// shortens the lives again after at most two periods.
    #[test]
    fn the_floor_rises_after_two_periods() {
        let mut floor = RoundTripFloor::default();
        let start = Instant::now();
        floor.record(10.0, start);
        let later = start + ROUND_TRIP_FLOOR_PERIOD;
        floor.record(300.0, later);
        assert_eq!(floor.ms(), 10.0, "one period on, the floor holds");
        floor.record(300.0, later + ROUND_TRIP_FLOOR_PERIOD);
        assert_eq!(floor.ms(), 300.0, "two periods on, it has risen");
    }
}
