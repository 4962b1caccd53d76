//! The clock of a real-time flight along a camera path, shared by the demo and the load
//! test's clients.

use std::time::{Duration, Instant};

/// Paces a flight of `frames` path frames at `fps`. The eye follows the clock: it is
/// where the path is `t·fps` frames in. A frame that takes longer does not slow the eye
/// down — the next one, drawn at once, shows it further on and the path frames between
/// are skipped, as in any real-time viewer — so a predictor sees the true motion, and
/// latency is real.
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
