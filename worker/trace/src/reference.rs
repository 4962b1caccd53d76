//! The reference frame: the whole scene ray-traced in perspective and lit per pixel with
//! the shared Phong model — the ground truth of every error measurement.
//!
//! One ray per pixel (through its centre) is what every frame compared with it does, so
//! a point-sampled reference measures how a renderer differs from exact geometry
//! sampled the same way. Detail finer than a pixel (a rough rock, thin leaves) makes any
//! two point samplings of it differ, though; `samples > 1` averages `n × n` stratified
//! rays per pixel — the anti-aliased image, closer to what the pixel really shows — to
//! measure against the truth instead.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::frame::{Frame, NO_OBJECT};
use relief_core::shading::{SurfacePoint, to_rgb8};

use crate::bvh::{Hit, PlaneRays, Ray};
use crate::tiles::{Block, par_fill_blocks};
use crate::tracer::SceneTracer;

/// Rays per pixel edge of the anti-aliased reference the reports and the demo compare
/// with, beside the point-sampled one.
pub const ANTIALIASED_SAMPLES: u32 = 3;

/// Renders `camera`'s view of the scene with `samples × samples` rays per pixel (box
/// filtered). An even count is taken as the next odd one: the middle ray then passes
/// through the pixel centre, and the object it hits is the pixel's object, so the
/// coverage is that of a point-sampled frame at any count. Runs on the current rayon
/// pool.
pub fn render_reference(tracer: &SceneTracer, camera: &Camera, samples: u32) -> Frame {
    let n = samples.max(1) | 1;
    let middle = (n * n / 2) as usize;
    let grid = SampleGrid::new(tracer, camera, n);
    let background = to_rgb8(tracer.background);
    // Points are lit relative to the eye (see [`SceneObject`](relief_core::scene::SceneObject)'s frames).
    let lighting = tracer.lighting.relative_to(camera.eye);
    let mut pixels = vec![(background, NO_OBJECT); camera.width as usize * camera.height as usize];
    par_fill_blocks(camera.width, camera.height, &mut pixels, |block, values| {
        let nearest = grid.nearest(tracer, block);
        // Every hit lit at once (the model runs several points per instruction).
        let points: Vec<SurfacePoint> = nearest
            .iter()
            .filter_map(|sample| {
                let (k, hit, ray) = sample.as_ref()?;
                let o = &tracer.objects[*k].object;
                let tri = hit.triangle as usize;
                Some(SurfacePoint {
                    albedo: o.mesh.albedo(tri, hit.u, hit.v),
                    normal: o.normal_to_world(o.mesh.shading_normal(tri, hit.u, hit.v)),
                    position: *ray * hit.t,
                    towards_eye: -ray.normalize(),
                    specular: o.specular,
                })
            })
            .collect();
        let mut lit = vec![Vec3::ZERO; points.len()];
        lighting.shade_all(&points, &mut lit);
        let mut lit = lit.into_iter();
        let shaded: Vec<(Vec3, u32)> = nearest
            .iter()
            .map(|sample| match sample {
                None => (tracer.background, NO_OBJECT),
                Some((k, ..)) => (lit.next().unwrap_or(tracer.background), *k as u32),
            })
            .collect();
        values.extend(shaded.chunks_exact((n * n) as usize).map(|pixel| {
            let sum: Vec3 = pixel.iter().map(|(c, _)| *c).sum();
            (to_rgb8(sum / pixel.len() as f32), pixel[middle].1)
        }));
    });
    let (color, object) = pixels.into_iter().unzip();
    Frame {
        width: camera.width,
        height: camera.height,
        color,
        object,
    }
}

/// A frame's samples as a grid `n` times finer than its pixels, sample `(i, j)` of
/// pixel `(x, y)` at fine cell `(n·x + i, n·y + j)`, its centre at pixel position
/// `(x + (i + ½)/n, y + (j + ½)/n)`. Each object wholly before the eye is traced as
/// beams from it ([`PlaneRays`] on the plane one unit before the eye); one reaching
/// behind the eye's plane, ray by ray. Each in its own frame: the camera moved into
/// it ([`SceneObject::local_camera`](relief_core::scene::SceneObject::local_camera)),
/// its hits' depths back in the world's metres.
struct SampleGrid<'a> {
    camera: &'a Camera,
    n: u32,
    /// How each object is traced, and its camera and world metres per metre of its
    /// frame.
    tracing: Vec<(Tracing, Camera, f32)>,
}

/// How a reference traces one object.
enum Tracing {
    /// Block by block, as beams from the eye.
    Beams(PlaneRays),
    /// One ray at a time from the eye, in the object's frame.
    RayByRay,
    /// Not at all: it lies wholly behind the eye.
    Behind,
}

/// A sample's nearest hit: the object, the hit (`t` in the world's view depth, so
/// that the point is `eye + ray·t`) and the sample's ray in the world, scaled to a
/// unit forward component.
type Sample = Option<(usize, Hit, Vec3)>;

impl<'a> SampleGrid<'a> {
    fn new(tracer: &SceneTracer, camera: &'a Camera, n: u32) -> Self {
        let h = camera.height as f32;
        let tan_half = camera.tan_half_fov();
        let tracing = tracer
            .objects
            .iter()
            .map(|o| {
                let (local, bounds) = (o.object.local_camera(camera), &o.object.local_bounds);
                // `Camera::ray` at pixel position (0, 0), and per fine cell.
                let corner_ray = local.ray(0.0, 0.0) * PLANE_DEPTH;
                let a = local.ray_x_step() * (PLANE_DEPTH / n as f32);
                let b = -local.up * (2.0 * tan_half / h * PLANE_DEPTH / n as f32);
                let depths = bounds.corners().map(|p| local.to_view(p).z);
                let near = depths.iter().copied().fold(f32::INFINITY, f32::min);
                let far = depths.iter().copied().fold(f32::NEG_INFINITY, f32::max);
                // (`t` is the depth past the plane.)
                let t_max = (far - PLANE_DEPTH) * (1.0 + BEAM_DEPTH_MARGIN) + BEAM_DEPTH_MARGIN;
                let fine_enough = || {
                    let samples = footprint_pixels(&local, bounds) * (n * n) as f32;
                    o.object.mesh.triangle_count() as f32 <= BEAM_MAX_TRIANGLES_PER_SAMPLE * samples.max(1.0)
                };
                let eye = local.eye_f32();
                let beams = (near > 0.0
                    && far.is_finite()
                    && within_beam_tangent(&local, bounds)
                    && fine_enough())
                .then(|| {
                    PlaneRays::from_centre(eye, eye + corner_ray, a, b, local.forward, -PLANE_DEPTH, t_max)
                })
                .flatten();
                let tracing = match beams {
                    Some(beams) => Tracing::Beams(beams),
                    None if far <= 0.0 => Tracing::Behind,
                    None => Tracing::RayByRay,
                };
                (tracing, local, o.object.depth_scale())
            })
            .collect();
        SampleGrid { camera, n, tracing }
    }

    /// The nearest hit of each sample of the pixels of `block`, pixel by pixel (in
    /// [`Block::pixels`] order), each pixel's samples row by row.
    fn nearest(&self, tracer: &SceneTracer, block: Block) -> Vec<Sample> {
        let n = self.n;
        let fine = Block {
            x0: block.x0 * n,
            y0: block.y0 * n,
            width: block.width * n,
            height: block.height * n,
        };
        // Fine cell (fx, fy) of the block's samples, at its place in the output.
        let index = |fx: u32, fy: u32| {
            let (dx, dy) = (fx - fine.x0, fy - fine.y0);
            let pixel = (dy / n) * block.width + dx / n;
            ((pixel * n + dy % n) * n + dx % n) as usize
        };
        let ray_of = |fx: u32, fy: u32| {
            let cell = 1.0 / n as f32;
            self.camera
                .ray((fx as f32 + 0.5) * cell, (fy as f32 + 0.5) * cell)
        };
        let mut nearest: Vec<Sample> = vec![None; fine.pixels().count()];
        let mut keep = |at: usize, k: usize, hit: Hit, ray: Vec3| {
            if nearest[at].is_none_or(|(_, best, _)| hit.t < best.t) {
                nearest[at] = Some((k, hit, ray));
            }
        };
        let mut hits = Vec::new();
        for ((k, o), (tracing, local, scale)) in tracer.objects.iter().enumerate().zip(&self.tracing) {
            match tracing {
                Tracing::Behind => {}
                Tracing::Beams(beam) => {
                    for sub in fine.tiles() {
                        hits.clear();
                        hits.resize((sub.width * sub.height) as usize, None);
                        o.bvh.intersect_block(beam, sub, &mut hits);
                        for ((fx, fy), hit) in sub.pixels().zip(&hits) {
                            if let Some(hit) = hit {
                                // Depth past the plane to view depth, in the world.
                                let hit = Hit {
                                    t: (hit.t + PLANE_DEPTH) * scale,
                                    ..*hit
                                };
                                keep(index(fx, fy), k, hit, ray_of(fx, fy));
                            }
                        }
                    }
                }
                Tracing::RayByRay => {
                    let cells: Vec<(u32, u32)> = fine.pixels().collect();
                    let cell = 1.0 / n as f32;
                    let rays: Vec<Ray> = cells
                        .iter()
                        .map(|&(fx, fy)| Ray {
                            origin: local.eye_f32(),
                            direction: local
                                .ray((fx as f32 + 0.5) * cell, (fy as f32 + 0.5) * cell)
                                .normalize(),
                            t_min: 0.0,
                            t_max: f32::INFINITY,
                        })
                        .collect();
                    hits.clear();
                    hits.resize(rays.len(), None);
                    o.bvh.intersect_batch(&rays, &mut hits);
                    for (&(fx, fy), hit) in cells.iter().zip(&hits) {
                        if let Some(hit) = hit {
                            let ray = ray_of(fx, fy);
                            // Distance along the unit ray to view depth, in the world
                            // (a turn keeps the ray's length).
                            let hit = Hit {
                                t: hit.t / ray.length() * scale,
                                ..*hit
                            };
                            keep(index(fx, fy), k, hit, ray);
                        }
                    }
                }
            }
        }
        nearest
    }
}

/// The pixels of the screen the projection of `bounds` spans (its bounding rectangle),
/// for bounds wholly before the eye.
fn footprint_pixels(camera: &Camera, bounds: &relief_core::bounds::Aabb) -> f32 {
    let (w, h) = (camera.width as f32, camera.height as f32);
    let projection = camera.projection();
    let (mut lo, mut hi) = (
        glam::Vec2::splat(f32::INFINITY),
        glam::Vec2::splat(f32::NEG_INFINITY),
    );
    for corner in bounds.corners() {
        let pixel = glam::Vec2::from(projection.view_to_pixel(camera.to_view(corner)));
        (lo, hi) = (lo.min(pixel), hi.max(pixel));
    }
    let (lo, hi) = (lo.max(glam::Vec2::ZERO), hi.min(glam::Vec2::new(w, h)));
    (hi.x - lo.x).max(0.0) * (hi.y - lo.y).max(0.0)
}

/// Beams pay where an object's triangles are few beside the samples it spans: a beam
/// projects every triangle in its block, a ray visits a few. Past this many triangles
/// a sample (over the bounds' screen rectangle), its rays are cast one at a time: at
/// 1 sample a pixel, the default scene's million-triangle rock from afar was slower
/// as beams.
const BEAM_MAX_TRIANGLES_PER_SAMPLE: f32 = 4.0;

/// Whether all of `bounds` (wholly before the eye) lies within
/// [`BEAM_MAX_TANGENT`] of the view axis.
fn within_beam_tangent(camera: &Camera, bounds: &relief_core::bounds::Aabb) -> bool {
    bounds.corners().iter().all(|&corner| {
        let v = camera.to_view(corner);
        v.x.abs().max(v.y.abs()) <= BEAM_MAX_TANGENT * v.z
    })
}

/// The widest a reference beam may see an object: the tangent of the largest angle
/// between the view axis and a ray to its bounds (about 84°). Nearer the eye's plane a
/// vertex projects so far out on the plane at depth 1 that its edge functions lose the
/// texel; such an object is cast ray by ray.
const BEAM_MAX_TANGENT: f32 = 10.0;

/// The view depth of the plane a reference's beams are cast through: where
/// [`Camera::ray`] reaches.
const PLANE_DEPTH: f32 = 1.0;

/// Relative margin on an object's far depth, for its beams' `t_max`: no hit on its
/// bounds' far side is lost to rounding.
const BEAM_DEPTH_MARGIN: f32 = 1e-4;
