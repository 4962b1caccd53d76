//! `frames.csv`: each frame flown, its time and where the time went, beside what the
//! manager did in it and, for the frames timed so, the same view drawn all as geometry
//! — so a median's surprises (a frame's median over the sum of its stages' medians) can
//! be traced to the frames that make them.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use relief_client::flight::FlightLog;
use relief_client::manager::RenderStages;

/// The columns of `frames.csv`, in order.
const HEADER: &str = "frame,path_frame,at_s,frame_ms,plan_ms,prewarp_ms,draw_ms,geometry_ms,shade_ms,\
                      unstaged_ms,texels_warped,geometry_frame_ms,stale,requests,arrived";

/// The all-geometry frames' times: one for every `every`-th frame flown, in order.
pub(super) struct Timed<'a> {
    pub(super) every: u32,
    pub(super) ms: &'a [f64],
}

impl Timed<'_> {
    /// The all-geometry time of frame `k` flown, if it was timed.
    fn of(&self, k: usize) -> Option<f64> {
        let every = self.every.max(1) as usize;
        k.is_multiple_of(every)
            .then(|| self.ms.get(k / every).copied())
            .flatten()
    }

    /// For each frame timed as geometry, its all-geometry time over its time as flown
    /// (`frame_ms`, one a frame flown).
    pub(super) fn ratios(&self, frame_ms: &[f64]) -> Vec<f64> {
        (frame_ms.iter().enumerate())
            .filter_map(|(k, &flown)| Some(self.of(k)? / flown))
            .filter(|ratio| ratio.is_finite())
            .collect()
    }
}

/// Writes `frames.csv` into `dir`: one row per frame flown, `render` the frames' stages
/// in the same order (a frame flown but not drawn has empty times), `geometry` the
/// all-geometry times of the frames timed so.
pub(super) fn write_frames_csv(
    dir: &Path,
    log: &FlightLog,
    render: &[RenderStages],
    geometry: Timed,
) -> Result<()> {
    let mut csv = String::from(HEADER);
    csv.push('\n');
    let cell = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
    for (k, record) in log.records.iter().enumerate() {
        // (Writing to a `String` cannot fail.)
        let _ = write!(csv, "{k},{},{:.4},", record.path_frame, record.at_s);
        match (log.frame_ms.get(k), render.get(k)) {
            (Some(&frame), Some(s)) => {
                let staged = record.plan_ms + s.prewarp_ms + s.draw_ms + s.geometry_ms + s.shade_ms;
                let _ = write!(
                    csv,
                    "{frame:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{},",
                    record.plan_ms,
                    s.prewarp_ms,
                    s.draw_ms,
                    s.geometry_ms,
                    s.shade_ms,
                    frame - staged,
                    s.texels_warped
                );
            }
            _ => {
                let _ = write!(csv, ",{:.3},,,,,,,", record.plan_ms);
            }
        }
        let _ = writeln!(
            csv,
            "{},{},{},{}",
            cell(geometry.of(k)),
            u8::from(record.stale),
            record.requests,
            record.arrived
        );
    }
    std::fs::write(dir.join("frames.csv"), csv).context("writing frames.csv")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `every`-th frame has the next time, and no other frame one; the ratios pair
    /// them with the frames as flown.
    #[test]
    fn the_timed_frames_are_every_kth() {
        let timed = Timed {
            every: 10,
            ms: &[1.0, 2.0, 3.0],
        };
        assert_eq!(
            (timed.of(0), timed.of(10), timed.of(20)),
            (Some(1.0), Some(2.0), Some(3.0))
        );
        assert_eq!((timed.of(5), timed.of(30)), (None, None));
        // Paired with the frames as flown (the third flown in no time: left out).
        let flown: Vec<f64> = (0..31).map(|k| if k == 20 { 0.0 } else { 0.5 }).collect();
        assert_eq!(timed.ratios(&flown), [2.0, 4.0]);
    }
}
