//! `relief report …`: measurements written as CSV, JSON and plots.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{Context, Result, anyhow};
use clap::{Args, Subcommand};

use relief_lab::methods::Method;
use relief_lab::plot::register_font;
use relief_lab::report::plots::{plot_error_vs_angle, plot_error_vs_time, write_method_strip};
use relief_lab::report::{self, Options, Prediction, Row};
use relief_render::geometry::is_cheap;

use crate::progress;

#[derive(Subcommand)]
pub enum ReportCommand {
    /// Image error against display time for every object × method × texture size ×
    /// angle from the source eye.
    ErrorVsTime(ErrorVsTimeArgs),
}

#[derive(Args)]
pub struct ErrorVsTimeArgs {
    /// Built-in scene name, .toml scene file, or .obj, .gltf or .glb file.
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
    let scene = crate::args::load_scene(&args.scene)?;
    let objects: Vec<String> = match &args.object {
        Some(name) => vec![scene.object(name)?.name.clone()],
        None => scene
            .objects
            .iter()
            .filter(|o| !is_cheap(o))
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
        write_method_strip(strip, &args.out.join(format!("strip_{}.png", strip.object)))?;
    }
    if args.json {
        let mut out = std::io::stdout().lock();
        serde_json::to_writer(&mut out, rows)?;
        writeln!(out)?;
    }
    tracing::info!("{} rows -> {}", rows.len(), args.out.display());
    Ok(())
}
