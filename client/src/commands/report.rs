//! `relief report …`: measurements written as CSV, JSON and plots.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow};
use clap::{Args, Subcommand};
use plotters::prelude::*;

use relief_client::report::{self, Options, Prediction, Row, Strip};
use relief_client::warp::Method;
use relief_core::frame::Frame;
use relief_core::scene::Scene;

use crate::progress;

#[derive(Subcommand)]
pub enum ReportCommand {
    /// Image error against display time for every object × method × texture size ×
    /// angle from the source eye.
    ErrorVsTime(ErrorVsTimeArgs),
}

#[derive(Args)]
pub struct ErrorVsTimeArgs {
    /// Built-in scene name, .toml scene file, or .obj file.
    #[arg(long, default_value = "default")]
    scene: String,
    /// One object (default: every object with at least 1,000 triangles).
    #[arg(long)]
    object: Option<String>,
    /// Output directory: error_vs_time.csv, predicted_error.csv, error_vs_time.png,
    /// error_vs_angle.png, strip_OBJECT.png.
    #[arg(long)]
    out: PathBuf,
    /// Print the rows as a JSON array on stdout.
    #[arg(long)]
    json: bool,
    /// Timed runs per row (median reported), at least 1.
    #[arg(long, default_value = "5", value_parser = clap::value_parser!(u32).range(1..=1000))]
    runs: u32,
    /// Texture sizes, comma-separated.
    #[arg(long, default_value = "128,256,512", value_delimiter = ',', value_parser = crate::args::texture_size)]
    sizes: Vec<u32>,
    /// Angles between source and destination eye, degrees, comma-separated.
    #[arg(long, default_value = "0,1,2,5,10,20,40", value_delimiter = ',', allow_hyphen_values = true, value_parser = angle)]
    angles: Vec<f32>,
    /// Methods, comma-separated (default: all).
    #[arg(long, value_delimiter = ',')]
    methods: Vec<Method>,
    /// Frame edge in pixels (square frames).
    #[arg(long, default_value = "256", value_parser = crate::args::frame_edge)]
    frame_size: u32,
    /// Angle of the side-by-side strip, one of --angles [default: 10 if measured, else
    /// the largest].
    #[arg(long, allow_hyphen_values = true, value_parser = angle)]
    strip_angle: Option<f32>,
    /// Texture size of the strip, one of --sizes [default: 256 if measured, else the
    /// largest].
    #[arg(long, value_parser = crate::args::texture_size)]
    strip_size: Option<u32>,
}

/// The strip's `chosen` value, which must be one of `measured`; by default `preferred`
/// when measured, else the largest measured.
fn strip_choice<T: PartialOrd + Copy + std::fmt::Display>(
    flag: &str,
    chosen: Option<T>,
    preferred: T,
    measured: &[T],
) -> Result<T> {
    match chosen {
        Some(v) if measured.contains(&v) => Ok(v),
        Some(v) => Err(anyhow!("{flag} {v} is not one of the values measured ({})", {
            let list: Vec<String> = measured.iter().map(|m| m.to_string()).collect();
            list.join(", ")
        })),
        None if measured.contains(&preferred) => Ok(preferred),
        None => measured
            .iter()
            .copied()
            .reduce(|best, v| if v > best { v } else { best })
            .ok_or_else(|| anyhow!("{flag}: nothing is measured")),
    }
}

fn angle(text: &str) -> Result<f32, String> {
    match crate::args::finite(text)? {
        a if a.abs() <= 180.0 => Ok(a),
        a => Err(format!("{a} is not an angle in -180..=180 degrees")),
    }
}

pub fn run(command: ReportCommand) -> Result<()> {
    match command {
        ReportCommand::ErrorVsTime(args) => error_vs_time(args),
    }
}

fn error_vs_time(args: ErrorVsTimeArgs) -> Result<()> {
    let scene = Scene::load(&args.scene)?;
    let objects: Vec<String> = match &args.object {
        Some(name) => vec![scene.object(name)?.name.clone()],
        None => scene
            .objects
            .iter()
            .filter(|o| o.mesh.triangle_count() >= 1000)
            .map(|o| o.name.clone())
            .collect(),
    };
    if objects.is_empty() {
        return Err(anyhow!(
            "scene `{}` has no object with 1,000 triangles or more: name one with --object",
            scene.name
        ));
    }
    let methods = if args.methods.is_empty() {
        Method::ALL.to_vec()
    } else {
        args.methods.clone()
    };
    let options = Options {
        sizes: args.sizes.clone(),
        angles: args.angles.clone(),
        methods,
        runs: args.runs as usize,
        frame_size: args.frame_size,
        distance: 3.0,
        strip: (
            strip_choice("--strip-angle", args.strip_angle, 10.0, &args.angles)?,
            strip_choice("--strip-size", args.strip_size, 256, &args.sizes)?,
        ),
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let total = objects.len() * options.angles.len() * (options.sizes.len() * options.methods.len() + 1);
    let bar = progress::bar(total as u64, "measuring");
    let measured = report::error_vs_time(&scene, &objects, &options, |row| {
        bar.set_message(format!(
            "{} {} {}² {}°",
            row.object, row.method, row.size, row.angle_deg
        ));
        bar.inc(1);
    })?;
    bar.finish_and_clear();
    let (rows, strips) = (&measured.rows, &measured.strips);
    let prediction_path = args.out.join("predicted_error.csv");
    let mut predictions = String::from(Prediction::CSV_HEADER) + "\n";
    for p in &measured.predictions {
        predictions += &p.csv();
        predictions.push('\n');
    }
    std::fs::write(&prediction_path, predictions)
        .with_context(|| format!("writing {}", prediction_path.display()))?;
    let csv_path = args.out.join("error_vs_time.csv");
    let mut csv = String::from(Row::CSV_HEADER) + "\n";
    for row in rows {
        csv += &row.csv();
        csv.push('\n');
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    register_font()?;
    plot_error_vs_time(rows, &options, &args.out.join("error_vs_time.png"))?;
    plot_error_vs_angle(rows, &options, &args.out.join("error_vs_angle.png"))?;
    for strip in strips {
        write_strip(strip, &args.out.join(format!("strip_{}.png", strip.object)))?;
    }
    if args.json {
        let mut out = std::io::stdout().lock();
        serde_json::to_writer(&mut out, rows)?;
        writeln!(out)?;
    }
    tracing::info!("{} rows -> {}", rows.len(), args.out.display());
    Ok(())
}

pub(crate) fn register_font() -> Result<()> {
    plotters::style::register_font("sans-serif", FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| anyhow!("the embedded plot font could not be loaded"))
}

/// Mean of `value` per (method, key) over the rows that pass `filter`.
fn mean_by(
    rows: &[Row],
    filter: impl Fn(&Row) -> bool,
    key: impl Fn(&Row) -> i64,
    value: impl Fn(&Row) -> (f64, f64),
) -> BTreeMap<String, BTreeMap<i64, (f64, f64)>> {
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

/// Palette entries kept for the report's series: geometry, then each method.
const SERIES_COLOURS: usize = 1 + Method::ALL.len();

/// The palette entry of a report series named after a method (or geometry), the same
/// in every chart whichever series it holds; `None` for other series.
fn series_colour(name: &str) -> Option<usize> {
    if name == report::GEOMETRY {
        return Some(0);
    }
    Method::ALL.iter().position(|m| m.name() == name).map(|k| 1 + k)
}

/// A line chart: one curve per series (points keyed for order), PNG at `path`.
pub(crate) fn draw_chart(
    path: &Path,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    series: &BTreeMap<String, BTreeMap<i64, (f64, f64)>>,
    log_x: bool,
) -> Result<()> {
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
    let x0 = if log_x { (x0 * 0.8).max(1e-4) } else { x0 - 1.0 };
    let x1 = if log_x { x1 * 1.25 } else { x1 + 1.0 };
    let (y0, y1) = ((y0 - 2.0).max(0.0), y1 + 2.0);
    {
        let root = BitMapBackend::with_buffer(&mut buffer, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("plot: {e}"))?;
        let mut builder = ChartBuilder::on(&root);
        builder
            .caption(title, ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(45)
            .y_label_area_size(55);
        macro_rules! draw {
            ($chart:expr) => {{
                let mut chart = $chart.map_err(|e| anyhow!("plot: {e}"))?;
                chart
                    .configure_mesh()
                    .x_desc(x_desc)
                    .y_desc(y_desc)
                    .draw()
                    .map_err(|e| anyhow!("plot: {e}"))?;
                for (i, (method, s)) in series.iter().enumerate() {
                    let color =
                        Palette99::pick(series_colour(method).unwrap_or(SERIES_COLOURS + i)).to_rgba();
                    let pts: Vec<(f64, f64)> = s.values().copied().collect();
                    chart
                        .draw_series(LineSeries::new(pts.clone(), color.stroke_width(2)))
                        .map_err(|e| anyhow!("plot: {e}"))?
                        .label(method.as_str())
                        .legend(move |(x, y)| {
                            PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                        });
                    chart
                        .draw_series(pts.iter().map(|&p| Circle::new(p, 3, color.filled())))
                        .map_err(|e| anyhow!("plot: {e}"))?;
                }
                chart
                    .configure_series_labels()
                    .position(SeriesLabelPosition::LowerRight)
                    .background_style(WHITE.mix(0.85))
                    .border_style(BLACK)
                    .draw()
                    .map_err(|e| anyhow!("plot: {e}"))?;
            }};
        }
        if log_x {
            draw!(builder.build_cartesian_2d((x0..x1).log_scale(), y0..y1));
        } else {
            draw!(builder.build_cartesian_2d(x0..x1, y0..y1));
        }
        root.present().map_err(|e| anyhow!("plot: {e}"))?;
    }
    image::save_buffer(path, &buffer, w, h, image::ColorType::Rgb8)
        .with_context(|| format!("writing {}", path.display()))
}

/// PSNR against display time: one curve per method through the texture sizes, at the
/// angle nearest 5°, averaged over objects.
fn plot_error_vs_time(rows: &[Row], options: &Options, path: &Path) -> Result<()> {
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
        |r| (r.ms, plotted_psnr(r.psnr_db)),
    );
    draw_chart(
        path,
        &format!(
            "Impostor PSNR vs display time, {angle}° from the source eye (texture sizes; mean over objects)"
        ),
        ("display time per frame (ms, log scale)", "PSNR (dB)"),
        &series,
        true,
    )
}

/// PSNR against the angle from the source eye, per method, at the strip's texture size.
fn plot_error_vs_angle(rows: &[Row], options: &Options, path: &Path) -> Result<()> {
    let size = options.strip.1;
    let series = mean_by(
        rows,
        |r| r.size == size,
        |r| (r.angle_deg * 1000.0) as i64,
        |r| (r.angle_deg as f64, plotted_psnr(r.psnr_db)),
    );
    draw_chart(
        path,
        &format!("Impostor PSNR vs angle from the source eye ({size}² textures; mean over objects)"),
        ("angle between source and destination eye (degrees)", "PSNR (dB)"),
        &series,
        false,
    )
}

/// Height of the strip's row of column names, pixels.
const LABEL_HEIGHT: u32 = 22;

/// Reference and each method side by side, each column named; below each method, its
/// difference from the reference (×4).
fn write_strip(strip: &Strip, path: &Path) -> Result<()> {
    let (fw, fh) = (strip.reference.width, strip.reference.height);
    if strip.frames.is_empty() || fw <= 1 {
        return Ok(());
    }
    let columns = 1 + strip.frames.len() as u32;
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
    blit(&strip.reference, 0, 0);
    for (i, (_, frame)) in strip.frames.iter().enumerate() {
        blit(frame, i as u32 + 1, 0);
        let mut diff = frame.clone();
        for (d, r) in diff.color.iter_mut().zip(&strip.reference.color) {
            *d = [0, 1, 2].map(|c| ((d[c] as i32 - r[c] as i32).unsigned_abs() * 4).min(255) as u8);
        }
        blit(&diff, i as u32 + 1, 1);
    }
    let names = std::iter::once("reference".to_string()).chain(strip.frames.iter().map(|(m, _)| m.name()));
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (width, height)).into_drawing_area();
        let style = ("sans-serif", 16).into_font().color(&BLACK);
        // (Cut to the column, about 9 pixels a character, so names never run together.)
        let fits = ((fw as usize).saturating_sub(8) / 9).max(1);
        for (col, name) in names.enumerate() {
            let at = ((col as u32 * fw + 4) as i32, 3);
            let name: String = name.chars().take(fits).collect();
            root.draw_text(&name, &style, at)
                .map_err(|e| anyhow!("strip: {e}"))?;
        }
        root.present().map_err(|e| anyhow!("strip: {e}"))?;
    }
    image::save_buffer(path, &rgb, width, height, image::ColorType::Rgb8)
        .with_context(|| format!("writing {}", path.display()))
}
