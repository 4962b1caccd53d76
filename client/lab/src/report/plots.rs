//! The report's pictures: PSNR against display time and against angle, one curve per
//! method (each method the same colour in every chart), and the side-by-side strips.

use std::collections::BTreeMap;
use std::path::Path;

use super::{GEOMETRY, Options, Row, Strip};
use crate::methods::Method;
use crate::plot::{Chart, Curve, PlotError, write_strip};

/// PSNR against display time: one curve per method through the texture sizes, at the
/// measured angle nearest 5°, averaged over objects. The charts plot `psnr_whole_db`,
/// over every pixel either image shows: a method that leaves holes cannot rise above
/// one that fills them.
pub fn plot_error_vs_time(rows: &[Row], options: &Options, path: &Path) -> Result<(), PlotError> {
    let angle = options
        .angles
        .iter()
        .copied()
        .min_by(|a, b| (a - 5.0).abs().total_cmp(&(b - 5.0).abs()))
        .unwrap_or(5.0);
    let series = mean_by(
        rows,
        |r| r.angle_deg == angle,
        |r| r.size as i64,
        |r| (r.ms, plotted_psnr(r.psnr_whole_db)),
    );
    Chart {
        title: &format!(
            "Impostor PSNR vs display time, {angle}° from the source eye (texture sizes; mean over objects)"
        ),
        x_desc: "display time per frame (ms, log scale)",
        y_desc: "PSNR over every pixel either shows (dB)",
        log_x: true,
        log_y: false,
        colour: &series_colour,
        point_label: &|_| None,
    }
    .draw(path, &series)
}

/// PSNR against the angle from the source eye, per method, at the strip's texture size.
pub fn plot_error_vs_angle(rows: &[Row], options: &Options, path: &Path) -> Result<(), PlotError> {
    let size = options.strip.1;
    let series = mean_by(
        rows,
        |r| r.size == size,
        |r| (r.angle_deg * 1000.0) as i64,
        |r| (r.angle_deg as f64, plotted_psnr(r.psnr_whole_db)),
    );
    Chart {
        title: &format!("Impostor PSNR vs angle from the source eye ({size}² textures; mean over objects)"),
        x_desc: "angle between source and destination eye (degrees)",
        y_desc: "PSNR over every pixel either shows (dB)",
        log_x: false,
        log_y: false,
        colour: &series_colour,
        point_label: &|_| None,
    }
    .draw(path, &series)
}

/// Reference and each method side by side, each column named; below each method, its
/// difference from the reference (×4).
pub fn write_method_strip(strip: &Strip, path: &Path) -> Result<(), PlotError> {
    let frames: Vec<(String, relief_core::frame::Frame)> = strip
        .frames
        .iter()
        .map(|(method, frame)| (method.name(), frame.clone()))
        .collect();
    write_strip(&strip.reference, &frames, path)
}

/// Mean of `value` per (method, key) over the rows that pass `filter`.
fn mean_by(
    rows: &[Row],
    filter: impl Fn(&Row) -> bool,
    key: impl Fn(&Row) -> i64,
    value: impl Fn(&Row) -> (f64, f64),
) -> BTreeMap<String, Curve> {
    let mut sums: BTreeMap<String, BTreeMap<i64, (f64, f64, usize)>> = BTreeMap::new();
    for row in rows.iter().filter(|r| filter(r)) {
        let (x, y) = value(row);
        if !(x.is_finite() && y.is_finite()) {
            continue;
        }
        let e = sums
            .entry(row.method.clone())
            .or_default()
            .entry(key(row))
            .or_insert((0.0, 0.0, 0));
        e.0 += x;
        e.1 += y;
        e.2 += 1;
    }
    sums.into_iter()
        .map(|(m, series)| {
            (
                m,
                series
                    .into_iter()
                    .map(|(k, (x, y, n))| (k, (x / n as f64, y / n as f64)))
                    .collect(),
            )
        })
        .collect()
}

/// PSNR for plotting: identical images (infinite PSNR) sit at the top of the axis; NaN
/// (nothing compared: the method could not draw) stays NaN, which no curve plots.
fn plotted_psnr(psnr: f64) -> f64 {
    // (Not `min`: `NaN.min(60.0)` is 60, a perfect score for nothing drawn.)
    if psnr > 60.0 { 60.0 } else { psnr }
}

// Every method's colour is its own.
const _: () = assert!(Method::ALL.len() < crate::plot::NAMED_COLOURS);

/// The palette entry of a report series named after a method (or geometry), the same
/// in every chart whichever series it holds; `None` for other series.
fn series_colour(name: &str) -> Option<usize> {
    if name == GEOMETRY {
        return Some(0);
    }
    Method::ALL.iter().position(|m| m.name() == name).map(|k| 1 + k)
}
