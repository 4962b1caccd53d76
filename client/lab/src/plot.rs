//! Line charts and image strips drawn into PNG files: the reports' and the load test's
//! pictures. The font (DejaVu Sans) is embedded, so no system fonts are needed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use relief_core::frame::Frame;

/// A picture that could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("the embedded plot font could not be loaded")]
    Font,
    #[error("plot {}: {message}", path.display())]
    Draw { path: PathBuf, message: String },
    #[error("writing {}: {error}", path.display())]
    Write { path: PathBuf, error: image::ImageError },
}

/// Points of one curve: `x, y`, keyed so that they are drawn in key order.
pub type Curve = BTreeMap<i64, (f64, f64)>;

/// Registers the embedded font; call once before drawing.
pub fn register_font() -> Result<(), PlotError> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| PlotError::Font)
}

/// How a chart is laid out: its title, axis names (with units), and whether x is on a
/// log scale. `colour` picks a series' palette entry by its name (`None`: by position),
/// so that one series keeps its colour across charts; `point_label` names a point by
/// its key (`None`: unnamed).
pub struct Chart<'a> {
    pub title: &'a str,
    pub x_desc: &'a str,
    pub y_desc: &'a str,
    pub log_x: bool,
    /// A log scale for y: values from milliseconds to seconds on one plot.
    pub log_y: bool,
    pub colour: &'a dyn Fn(&str) -> Option<usize>,
    pub point_label: &'a dyn Fn(i64) -> Option<String>,
}

/// Colours reserved for series coloured by name (the report's geometry and eleven
/// methods); the others take the next.
pub const NAMED_COLOURS: usize = 12;

impl Chart<'_> {
    /// Draws one curve per series (every measured point marked) into a PNG at `path`.
    pub fn draw(&self, path: &Path, series: &BTreeMap<String, Curve>) -> Result<(), PlotError> {
        let fail = |e: &dyn std::fmt::Display| PlotError::Draw {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let (w, h) = (960u32, 600u32);
        let mut buffer = vec![255u8; (w * h * 3) as usize];
        let points: Vec<(f64, f64)> = series.values().flat_map(|s| s.values().copied()).collect();
        let (mut x0, mut x1) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.0), b.max(p.0))
            });
        let (mut y0, mut y1) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
                (a.min(p.1), b.max(p.1))
            });
        if !x0.is_finite() {
            (x0, x1, y0, y1) = (0.01, 1.0, 0.0, 60.0);
        }
        // (Linear: a twentieth of the span each side, so seconds and degrees alike.)
        let pad = if x1 > x0 { 0.05 * (x1 - x0) } else { 1.0 };
        let x0 = if self.log_x {
            (x0 * 0.8).max(1e-4)
        } else {
            x0 - pad
        };
        let x1 = if self.log_x { x1 * 1.25 } else { x1 + pad };
        let (y0, y1) = if self.log_y {
            ((y0 * 0.8).max(1e-4), y1 * 1.25)
        } else {
            ((y0 - 2.0).max(0.0), y1 + 2.0)
        };
        {
            let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| fail(&e))?;
            let mut builder = ChartBuilder::on(&root);
            builder
                .caption(self.title, ("sans-serif", 22))
                .margin(12)
                .x_label_area_size(45)
                .y_label_area_size(55);
            macro_rules! draw {
                ($chart:expr) => {{
                    let mut chart = $chart.map_err(|e| fail(&e))?;
                    chart
                        .configure_mesh()
                        .x_labels(12)
                        .y_labels(12)
                        .x_desc(self.x_desc)
                        .y_desc(self.y_desc)
                        .draw()
                        .map_err(|e| fail(&e))?;
                    for (i, (name, s)) in series.iter().enumerate() {
                        let colour = strong_colour((self.colour)(name).unwrap_or(NAMED_COLOURS + i));
                        let pts: Vec<(f64, f64)> = s.values().copied().collect();
                        chart
                            .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
                            .map_err(|e| fail(&e))?
                            .label(name.as_str())
                            .legend(move |(x, y)| {
                                PathElement::new(vec![(x, y), (x + 20, y)], colour.stroke_width(2))
                            });
                        chart
                            .draw_series(pts.iter().map(|&p| Circle::new(p, 3, colour.filled())))
                            .map_err(|e| fail(&e))?;
                        let labels = s
                            .iter()
                            .filter_map(|(&key, &p)| Some((p, (self.point_label)(key)?)));
                        chart
                            .draw_series(labels.map(|(p, text)| {
                                Text::new(text, p, ("sans-serif", 13).into_font().color(&colour))
                            }))
                            .map_err(|e| fail(&e))?;
                    }
                    chart
                        .configure_series_labels()
                        .position(SeriesLabelPosition::LowerRight)
                        .background_style(WHITE.mix(0.85))
                        .border_style(BLACK)
                        .draw()
                        .map_err(|e| fail(&e))?;
                }};
            }
            match (self.log_x, self.log_y) {
                (true, true) => draw!(builder.build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())),
                (true, false) => draw!(builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1)),
                (false, true) => draw!(builder.build_cartesian_2d(x0..x1, (y0..y1).log_scale())),
                (false, false) => draw!(builder.build_cartesian_2d(x0..x1, y0..y1)),
            }
            root.present().map_err(|e| fail(&e))?;
        }
        save(path, &buffer, w, h)
    }
}

/// Saturated colours, each far from the others and from the white background (the
/// stock palettes hold pale ones that vanish on white): series get them in turn.
const STRONG: [(u8, u8, u8); 16] = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (80, 80, 80),
    (188, 189, 34),
    (23, 190, 207),
    (0, 0, 128),
    (128, 0, 0),
    (0, 100, 0),
    (255, 0, 255),
    (0, 0, 0),
    (205, 133, 0),
];

/// The `k`-th of [`STRONG`], round again past the last.
fn strong_colour(k: usize) -> RGBAColor {
    let (r, g, b) = STRONG[k % STRONG.len()];
    RGBColor(r, g, b).to_rgba()
}

/// Height of a strip's row of column names, pixels.
const LABEL_HEIGHT: u32 = 22;

/// `reference` and each named frame side by side, each column named above it; below
/// each frame, its difference from the reference (×4). Frames must match the
/// reference's size. Nothing is written for no frames.
pub fn write_strip(reference: &Frame, frames: &[(String, Frame)], path: &Path) -> Result<(), PlotError> {
    let (fw, fh) = (reference.width, reference.height);
    if frames.is_empty() || fw <= 1 {
        return Ok(());
    }
    let columns = 1 + frames.len() as u32;
    let (width, height) = (fw * columns, LABEL_HEIGHT + 2 * fh);
    let mut rgb = vec![255u8; (width * height * 3) as usize];
    let mut blit = |frame: &Frame, col: u32, row: u32| {
        for y in 0..fh {
            for x in 0..fw {
                let at = (((LABEL_HEIGHT + row * fh + y) * width + col * fw + x) * 3) as usize;
                rgb[at..at + 3].copy_from_slice(&frame.color[(y * fw + x) as usize]);
            }
        }
    };
    blit(reference, 0, 0);
    for (i, (_, frame)) in frames.iter().enumerate() {
        blit(frame, i as u32 + 1, 0);
        let mut diff = frame.clone();
        for (d, r) in diff.color.iter_mut().zip(&reference.color) {
            *d = [0, 1, 2].map(|c| ((d[c] as i32 - r[c] as i32).unsigned_abs() * 4).min(255) as u8);
        }
        blit(&diff, i as u32 + 1, 1);
    }
    let names = std::iter::once("reference").chain(frames.iter().map(|(name, _)| name.as_str()));
    {
        let fail = |e: &dyn std::fmt::Display| PlotError::Draw {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let style = ("sans-serif", 16).into_font().color(&BLACK);
        // (Cut to the column, about 9 pixels a character, so names never run together.)
        let fits = ((fw as usize).saturating_sub(8) / 9).max(1);
        for (col, name) in names.enumerate() {
            let at = ((col as u32 * fw + 4) as i32, 3);
            let name: String = name.chars().take(fits).collect();
            root.draw_text(&name, &style, at).map_err(|e| fail(&e))?;
        }
        root.present().map_err(|e| fail(&e))?;
    }
    save(path, &rgb, width, height)
}

fn save(path: &Path, rgb: &[u8], width: u32, height: u32) -> Result<(), PlotError> {
    image::save_buffer(path, rgb, width, height, image::ColorType::Rgb8).map_err(|error| PlotError::Write {
        path: path.to_path_buf(),
        error,
    })
}
