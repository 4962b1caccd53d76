//! `frames.csv`: each frame flown, its time and where the time went, beside what the
//! manager did in it — so a median's surprises (a frame's median over the sum of its
//! stages' medians) can be traced to the frames that make them.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use relief_client::flight::FlightLog;
use relief_client::manager::RenderStages;

/// The columns of `frames.csv`, in order.
const HEADER: &str = "frame,path_frame,at_s,frame_ms,plan_ms,prewarp_ms,draw_ms,geometry_ms,shade_ms,\
                      unstaged_ms,texels_warped,stale,requests,arrived";

/// Writes `frames.csv` into `dir`: one row per frame flown, `render` the frames' stages
/// in the same order (a frame flown but not drawn has empty times).
pub(super) fn write_frames_csv(dir: &Path, log: &FlightLog, render: &[RenderStages]) -> Result<()> {
    let mut csv = String::from(HEADER);
    csv.push('\n');
    for (k, record) in log.records.iter().enumerate() {
        let (frame_ms, stages) = (log.frame_ms.get(k), render.get(k));
        // (Writing to a `String` cannot fail.)
        let _ = write!(csv, "{k},{},{:.4},", record.path_frame, record.at_s);
        match (frame_ms, stages) {
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
            "{},{},{}",
            u8::from(record.stale),
            record.requests,
            record.arrived
        );
    }
    std::fs::write(dir.join("frames.csv"), csv).context("writing frames.csv")
}
