//! The error-against-run-time measurement: every object × method × texture size ×
//! angle between the source eye (where the texture was baked) and the destination eye
//! (orbiting the object at a fixed distance), timed and compared with the ray-traced
//! reference.

pub mod plots;

use serde::Serialize;

use relief_core::frame::Frame;
use relief_core::relief::DepthBits;
use relief_core::scene::Scene;

use relief_render::gbuffer::GBuffer;
use relief_render::geometry::render_geometry;
use relief_render::impostor::Impostor;
use relief_render::validity::critical::{CRITICAL_REGIONS, CriticalPoints, measured_gap};
use relief_render::warp::params::WarpParams;
use relief_render::warp::sprite::Sprite;
use relief_trace::ANTIALIASED_SAMPLES;

use crate::methods::{Method, display};
use crate::solo::{Solo, SoloError};
use crate::timing::median_ms_after;

/// What to measure.
#[derive(Debug, Clone)]
pub struct Options {
    pub sizes: Vec<u32>,
    pub angles: Vec<f32>,
    pub methods: Vec<Method>,
    /// Timed runs per row, after a warm-up (the median is reported).
    pub runs: usize,
    /// Edge of the square frames, pixels.
    pub frame_size: u32,
    /// Orbit radius in bounding radii.
    pub distance: f32,
    /// The angle and size whose frames are kept for the side-by-side strip.
    pub strip: (f32, u32),
}

/// The method name of the rows that draw the object as exact geometry.
pub const GEOMETRY: &str = "geometry";

/// One measurement: a CSV row.
#[derive(Debug, Clone, Serialize)]
pub struct Row {
    pub object: String,
    /// A display method, or [`GEOMETRY`]: the object rasterized, one sample per pixel
    /// (the rows with `size` 0, since no texture is involved).
    pub method: String,
    pub size: u32,
    pub angle_deg: f32,
    /// Median display time (warp + reconstruction into the frame's G-buffer; for
    /// geometry, rasterization and shading), ms.
    pub ms: f64,
    /// Against the point-sampled reference (one ray through each pixel centre), over
    /// the pixels both show; `ssim` too. `hole_frac`: of the pixels either shows, those
    /// only one does; `psnr_whole_db`: over every pixel either shows, so a method that
    /// leaves the object half empty cannot score as if it had drawn it (see
    /// [`ImageError`](crate::image_error::ImageError)).
    #[serde(serialize_with = "crate::image_error::serialize_psnr")]
    pub psnr_db: f64,
    pub ssim: f64,
    pub hole_frac: f64,
    #[serde(serialize_with = "crate::image_error::serialize_psnr")]
    pub psnr_whole_db: f64,
    /// `hole_frac` within [`MAX_HOLE_FRAC`](crate::image_error::MAX_HOLE_FRAC): only
    /// then does `psnr_db` speak for the method.
    pub covers_reference: bool,
    /// Against the anti-aliased reference ([`ANTIALIASED_SAMPLES`]² rays per pixel).
    /// Exact geometry sampled once per pixel does not reach it either: its
    /// `psnr_aa_db` is the floor that detail finer than a pixel sets for every
    /// one-sample display.
    #[serde(serialize_with = "crate::image_error::serialize_psnr")]
    pub psnr_aa_db: f64,
}

impl Row {
    pub const CSV_HEADER: &'static str =
        "object,method,size,angle_deg,ms,psnr_db,ssim,hole_frac,psnr_whole_db,covers_reference,psnr_aa_db";

    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{},{:.4},{:.3},{:.5},{:.5},{:.3},{},{:.3}",
            self.object,
            self.method,
            self.size,
            self.angle_deg,
            self.ms,
            self.psnr_db,
            self.ssim,
            self.hole_frac,
            self.psnr_whole_db,
            self.covers_reference,
            self.psnr_aa_db
        )
    }
}

/// Predicted against measured warp error for one object, size and angle.
#[derive(Debug, Clone, Serialize)]
pub struct Prediction {
    pub object: String,
    pub size: u32,
    pub angle_deg: f32,
    /// Gap (texels) predicted from the single critical point (5.5).
    pub predicted_gap: f32,
    /// Sum of the 8×8 regions' predicted gaps (5.6).
    pub predicted_region_gap: f32,
    /// The widest of the regions' predicted gaps.
    pub predicted_worst_region_gap: f32,
    /// The widest gap the pre-warp really opens (texels).
    pub measured_gap: f32,
    /// The interleaved warp's image error at this angle.
    #[serde(serialize_with = "crate::image_error::serialize_psnr")]
    pub psnr_db: f64,
    pub hole_frac: f64,
}

impl Prediction {
    pub const CSV_HEADER: &'static str = "object,size,angle_deg,predicted_gap,predicted_region_gap,predicted_worst_region_gap,measured_gap,psnr_db,hole_frac";

    pub fn csv(&self) -> String {
        format!(
            "{},{},{},{:.4},{:.4},{:.4},{:.4},{:.3},{:.5}",
            self.object,
            self.size,
            self.angle_deg,
            self.predicted_gap,
            self.predicted_region_gap,
            self.predicted_worst_region_gap,
            self.measured_gap,
            self.psnr_db,
            self.hole_frac
        )
    }
}

/// Everything one run of the report measured.
pub struct Measurements {
    pub rows: Vec<Row>,
    pub predictions: Vec<Prediction>,
    pub strips: Vec<Strip>,
}

/// The frames of one object at the strip's angle and size.
pub struct Strip {
    pub object: String,
    pub reference: Frame,
    pub frames: Vec<(Method, Frame)>,
}

/// Measures `objects` of `scene`; `on_row` sees each row as it is made (progress).
pub fn error_vs_time(
    scene: &Scene,
    objects: &[String],
    options: &Options,
    mut on_row: impl FnMut(&Row),
) -> Result<Measurements, SoloError> {
    let mut rows = Vec::new();
    let mut strips = Vec::new();
    let mut predictions = Vec::new();
    for name in objects {
        let solo = Solo::new(scene, name, options.distance)?;
        let source_eye = solo.eye(0.0);
        let source_camera = solo.camera(source_eye, options.frame_size)?;
        let cameras = options
            .angles
            .iter()
            .map(|&a| solo.camera(solo.eye(a), options.frame_size))
            .collect::<Result<Vec<_>, _>>()?;
        let references: Vec<Frame> = cameras.iter().map(|c| solo.reference(c, 1)).collect();
        let antialiased: Vec<Frame> = cameras
            .iter()
            .map(|c| solo.reference(c, ANTIALIASED_SAMPLES))
            .collect();
        // The floor: the object as exact geometry, one sample per pixel.
        for (k, &angle) in options.angles.iter().enumerate() {
            let camera = &cameras[k];
            let mut drawn = (
                GBuffer::new(camera.width, camera.height),
                Frame::new(1, 1, [0; 3]),
            );
            let ms = median_ms_after(
                options.runs,
                &mut drawn,
                |_| {},
                |(gbuffer, frame)| *frame = render_geometry(&solo.scene, camera, gbuffer),
            );
            let frame = drawn.1;
            let error = solo.error(&frame, &references[k]);
            let row = Row {
                object: name.clone(),
                method: GEOMETRY.into(),
                size: 0,
                angle_deg: angle,
                ms,
                psnr_db: error.psnr_db,
                ssim: error.ssim,
                hole_frac: error.hole_frac,
                psnr_whole_db: error.psnr_whole_db,
                covers_reference: error.covers_reference(),
                psnr_aa_db: solo.error(&frame, &antialiased[k]).psnr_db,
            };
            on_row(&row);
            rows.push(row);
        }
        let mut strip = Strip {
            object: name.clone(),
            reference: Frame::new(1, 1, [0; 3]),
            frames: Vec::new(),
        };
        for &size in &options.sizes {
            let texture = solo.bake(source_eye, size, DepthBits::Eight)?;
            let impostor = Impostor::new(texture);
            let critical = CriticalPoints::find(&impostor.texture, CRITICAL_REGIONS, CRITICAL_REGIONS);
            // The sprite is what the sources' best warp showed at the source eye.
            let mut at_source = GBuffer::new(options.frame_size, options.frame_size);
            let sprite = display(Method::Interleaved, &impostor, 0, &source_camera, &mut at_source)
                .ok()
                .and_then(|()| Sprite::capture(&at_source, 0));
            for (k, &angle) in options.angles.iter().enumerate() {
                let camera = &cameras[k];
                let keep = (angle, size) == options.strip;
                if keep {
                    strip.reference = references[k].clone();
                }
                for &method in &options.methods {
                    // (The G-buffer, and whether the method refused to draw.)
                    let mut drawn = (GBuffer::new(camera.width, camera.height), false);
                    let ms = median_ms_after(
                        options.runs,
                        &mut drawn,
                        |(gbuffer, _)| gbuffer.clear(),
                        |(gbuffer, failed)| {
                            let shown = match method {
                                Method::Sprite => {
                                    if let Some(s) = &sprite {
                                        s.draw(gbuffer);
                                    }
                                    Ok(())
                                }
                                _ => display(method, &impostor, 0, camera, gbuffer),
                            };
                            *failed |= shown.is_err();
                        },
                    );
                    let (gbuffer, failed) = drawn;
                    let frame = gbuffer.shade(&solo.scene, camera);
                    let error = solo.error(&frame, &references[k]);
                    let row = Row {
                        object: name.clone(),
                        method: method.name(),
                        size,
                        angle_deg: angle,
                        ms: if failed { f64::NAN } else { ms },
                        psnr_db: error.psnr_db,
                        ssim: error.ssim,
                        hole_frac: error.hole_frac,
                        psnr_whole_db: error.psnr_whole_db,
                        covers_reference: error.covers_reference(),
                        psnr_aa_db: solo.error(&frame, &antialiased[k]).psnr_db,
                    };
                    on_row(&row);
                    if method == Method::Interleaved
                        && let Ok(params) = WarpParams::new(&impostor.texture, camera.eye_f32())
                    {
                        predictions.push(Prediction {
                            object: name.clone(),
                            size,
                            angle_deg: angle,
                            predicted_gap: critical.global_gap(&params),
                            predicted_region_gap: critical.region_gap(&params),
                            predicted_worst_region_gap: critical.worst_region_gap(&params),
                            measured_gap: measured_gap(&impostor.texture, &params),
                            psnr_db: row.psnr_db,
                            hole_frac: row.hole_frac,
                        });
                    }
                    rows.push(row);
                    if keep {
                        strip.frames.push((method, frame));
                    }
                }
            }
        }
        strips.push(strip);
    }
    Ok(Measurements {
        rows,
        predictions,
        strips,
    })
}
