//! `frames.csv`: each frame flown, its time and where the time went, beside what the
//! manager did in it and, for the frames timed so, the same view drawn all as geometry
//! — so a median's surprises (a frame's median over the sum of its stages' medians) can
//! be traced to the frames that make them; and the frames' paired ratio to geometry.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result, ensure};
use relief_client::flight::{FlightLog, FrameRecord};
use relief_client::manager::RenderStages;

/// The columns of `frames.csv`, in order.
const HEADER: &str = "frame,path_frame,at_s,frame_ms,plan_ms,prewarp_ms,draw_ms,geometry_ms,shade_ms,\
                      unstaged_ms,texels_warped,geometry_frame_ms,stale,requests,arrived";

/// One frame flown and drawn: what the manager did, the frame's time and stages, and
/// the same view's time all as geometry where it was timed so.
struct Frame<'a> {
    record: &'a FrameRecord,
    frame_ms: f64,
    stages: &'a RenderStages,
    geometry_ms: Option<f64>,
}

/// Every frame of a flight in which each frame flown was drawn (the demo's).
pub(super) struct FrameTimings<'a> {
    frames: Vec<Frame<'a>>,
}

impl<'a> FrameTimings<'a> {
    /// The frames of `log`, with `render` their stages in order, and `geometry_ms[i]`
    /// the all-geometry time of frame `geometry_frames[i]` (indices of frames flown).
    /// An error if `log` or `render` do not hold one entry for each frame flown.
    pub(super) fn new(
        log: &'a FlightLog,
        render: &'a [RenderStages],
        geometry_frames: &[usize],
        geometry_ms: &[f64],
    ) -> Result<FrameTimings<'a>> {
        let flown = log.records.len();
        ensure!(
            log.frame_ms.len() == flown && render.len() == flown,
            "a frame flown but not drawn: {flown} flown, {} timed, {} with stages",
            log.frame_ms.len(),
            render.len()
        );
        let mut geometry = vec![None; flown];
        for (&k, &ms) in geometry_frames.iter().zip(geometry_ms) {
            if let Some(slot) = geometry.get_mut(k) {
                *slot = Some(ms);
            }
        }
        let frames = (log.records.iter().zip(&log.frame_ms).zip(render).zip(geometry))
            .map(|(((record, &frame_ms), stages), geometry_ms)| Frame {
                record,
                frame_ms,
                stages,
                geometry_ms,
            })
            .collect();
        Ok(FrameTimings { frames })
    }

    /// For each frame timed as geometry that warped a texture, its all-geometry time
    /// over its time as flown.
    pub(super) fn paired_ratios(&self) -> Vec<f64> {
        (self.frames.iter())
            .filter(|f| f.stages.texels_warped > 0)
            .filter_map(|f| Some(f.geometry_ms? / f.frame_ms))
            .filter(|ratio| ratio.is_finite())
            .collect()
    }

    /// Writes `frames.csv` into `dir`.
    pub(super) fn write_csv(&self, dir: &Path) -> Result<()> {
        let mut csv = String::from(HEADER);
        csv.push('\n');
        for (k, f) in self.frames.iter().enumerate() {
            let (r, s) = (f.record, f.stages);
            let staged = r.plan_ms + s.prewarp_ms + s.draw_ms + s.geometry_ms + s.shade_ms;
            // (Writing to a `String` cannot fail.)
            let _ = writeln!(
                csv,
                "{k},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{},{},{},{},{}",
                r.path_frame,
                r.at_s,
                f.frame_ms,
                r.plan_ms,
                s.prewarp_ms,
                s.draw_ms,
                s.geometry_ms,
                s.shade_ms,
                f.frame_ms - staged,
                s.texels_warped,
                f.geometry_ms.map_or(String::new(), |ms| format!("{ms:.4}")),
                u8::from(r.stale),
                r.requests,
                r.arrived
            );
        }
        std::fs::write(dir.join("frames.csv"), csv).context("writing frames.csv")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The all-geometry times go to the frames named; the paired ratios are those of
    /// the frames timed so that warped a texture; a log with a frame not drawn is
    /// refused.
    #[test]
    fn frames_pair_with_their_geometry() {
        let record = FrameRecord::default();
        let log = FlightLog {
            records: vec![record; 4],
            frame_ms: vec![0.5, 0.5, 0.25, 0.5],
            ..FlightLog::default()
        };
        let warped = |texels_warped| RenderStages {
            texels_warped,
            ..RenderStages::default()
        };
        let render = [warped(10), warped(0), warped(10), warped(10)];
        // Frames 0, 1 and 2 timed as geometry; frame 1 warped nothing; a stray index
        // past the flight is dropped.
        let timings = FrameTimings::new(&log, &render, &[0, 1, 2, 9], &[1.0, 2.0, 3.0, 4.0]).unwrap();
        assert_eq!(timings.paired_ratios(), [2.0, 12.0]);
        let geometry: Vec<_> = timings.frames.iter().map(|f| f.geometry_ms).collect();
        assert_eq!(geometry, [Some(1.0), Some(2.0), Some(3.0), None]);
        assert!(FrameTimings::new(&log, &render[..3], &[], &[]).is_err());
    }
}
