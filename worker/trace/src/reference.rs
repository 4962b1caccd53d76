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
use crate::placements::BlockRays;
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
    render_reference_by(tracer, camera, samples, ObjectWalk::NearestFirst)
}

/// How a reference frame goes through a scene's objects for each block of pixels. The
/// frame is the same either way, bit for bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectWalk {
    /// The objects the top-level BVH finds in the block, nearest first, until the rest
    /// lie behind what is hit ([`Placements::nearest_first`](crate::placements::Placements::nearest_first)):
    /// [`render_reference`]'s.
    NearestFirst,
    /// Every object in turn: the baseline `relief bench reference` measures the other
    /// against.
    EveryObject,
}

/// [`render_reference`], going through the objects by `walk`.
pub fn render_reference_by(tracer: &SceneTracer, camera: &Camera, samples: u32, walk: ObjectWalk) -> Frame {
    let n = samples.max(1) | 1;
    let middle = (n * n / 2) as usize;
    let grid = SampleGrid::new(tracer, camera, n);
    let background = to_rgb8(tracer.background);
    // Points are lit relative to the eye (see [`SceneObject`](relief_core::scene::SceneObject)'s frames).
    let lighting = tracer.lighting.relative_to(camera.eye);
    let mut pixels = vec![(background, NO_OBJECT); camera.width as usize * camera.height as usize];
    par_fill_blocks(camera.width, camera.height, &mut pixels, |block, values| {
        let nearest = grid.nearest(tracer, block, walk);
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
    /// [`Block::pixels`] order), each pixel's samples row by row, of the objects `walk`
    /// goes through.
    fn nearest(&self, tracer: &SceneTracer, block: Block, walk: ObjectWalk) -> Vec<Sample> {
        let mut samples = BlockSamples::new(block, self.n);
        match walk {
            ObjectWalk::NearestFirst => {
                tracer.placements.nearest_first(&self.rays(block), |k| {
                    self.trace(tracer, k, &mut samples);
                    samples.farthest()
                });
            }
            ObjectWalk::EveryObject => {
                for k in 0..tracer.objects.len() {
                    self.trace(tracer, k, &mut samples);
                }
            }
        }
        samples.nearest
    }

    /// The rays through `block`'s pixels.
    fn rays(&self, block: Block) -> BlockRays {
        let corner = |x: u32, y: u32| (x as f32, y as f32);
        BlockRays::new(
            self.camera,
            corner(block.x0, block.y0),
            corner(block.x0 + block.width, block.y0 + block.height),
        )
    }

    /// The ray in the world of fine cell `(fx, fy)`, scaled to a unit forward
    /// component.
    fn ray_of(&self, fx: u32, fy: u32) -> Vec3 {
        let cell = 1.0 / self.n as f32;
        self.camera
            .ray((fx as f32 + 0.5) * cell, (fy as f32 + 0.5) * cell)
    }

    /// Traces object `k` through the block's samples, keeping its hits where nearer.
    fn trace(&self, tracer: &SceneTracer, k: usize, samples: &mut BlockSamples) {
        let (o, (tracing, local, scale)) = (&tracer.objects[k], &self.tracing[k]);
        let fine = samples.fine;
        // (The block's scratch buffer, taken while `samples` keeps hits.)
        let mut hits = std::mem::take(&mut samples.hits);
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
                            samples.keep(fx, fy, k, hit, || self.ray_of(fx, fy));
                        }
                    }
                }
            }
            Tracing::RayByRay => {
                let cells: Vec<(u32, u32)> = fine.pixels().collect();
                let cell = 1.0 / self.n as f32;
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
                        let ray = self.ray_of(fx, fy);
                        // Distance along the unit ray to view depth, in the world
                        // (a turn keeps the ray's length).
                        let hit = Hit {
                            t: hit.t / ray.length() * scale,
                            ..*hit
                        };
                        samples.keep(fx, fy, k, hit, || ray);
                    }
                }
            }
        }
        samples.hits = hits;
    }
}

/// The samples of one block of pixels, as a block of the fine grid, and the nearest
/// hit of each so far.
struct BlockSamples {
    fine: Block,
    n: u32,
    /// Pixels in a row of the block.
    width: u32,
    nearest: Vec<Sample>,
    /// Scratch for one object's hits over a tile.
    hits: Vec<Option<Hit>>,
}

impl BlockSamples {
    fn new(block: Block, n: u32) -> Self {
        let fine = Block {
            x0: block.x0 * n,
            y0: block.y0 * n,
            width: block.width * n,
            height: block.height * n,
        };
        BlockSamples {
            fine,
            n,
            width: block.width,
            nearest: vec![None; fine.pixels().count()],
            hits: Vec::new(),
        }
    }

    /// Keeps `hit` of object `k` at fine cell `(fx, fy)` if it is nearer than the
    /// sample's hit so far, or as near and of an object listed earlier: the same hit
    /// whatever order the objects come in.
    fn keep(&mut self, fx: u32, fy: u32, k: usize, hit: Hit, ray: impl FnOnce() -> Vec3) {
        let n = self.n;
        let (dx, dy) = (fx - self.fine.x0, fy - self.fine.y0);
        let pixel = (dy / n) * self.width + dx / n;
        let at = ((pixel * n + dy % n) * n + dx % n) as usize;
        let nearer = |&(best_k, best, _): &(usize, Hit, Vec3)| (hit.t, k) < (best.t, best_k);
        if self.nearest[at].as_ref().is_none_or(nearer) {
            self.nearest[at] = Some((k, hit, ray()));
        }
    }

    /// The farthest of the samples' nearest hits, as a view depth in the world;
    /// infinite while a sample has none.
    fn farthest(&self) -> f32 {
        (self.nearest.iter())
            .map(|sample| sample.as_ref().map_or(f32::INFINITY, |(_, hit, _)| hit.t))
            .fold(0.0, f32::max)
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

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};

    use relief_core::camera::Camera;
    use relief_core::scene::Scene;

    use super::*;

    /// A ground, a wall, and 60 small spheres and knots in rows behind it and before
    /// it — turned, scaled, one across the eye's plane — and the eye far from the origin.
    fn crowd(origin: DVec3) -> Scene {
        let mut text = String::from(
            r#"
            [[objects]]
            name = "ground"
            generator = { kind = "plane", size = 80.0, divisions = 1 }
            [[objects]]
            name = "wall"
            generator = { kind = "plane", size = 6.0, divisions = 2 }
            translate = [0, 1, -2]
            rotate_deg = [90, 0, 0]
            [[objects]]
            name = "sphere"
            generator = { kind = "sphere", subdivisions = 2 }
            instances = [
            "#,
        );
        for k in 0..30 {
            let (x, z) = ((k % 6) as f64 * 1.7 - 4.0, -(k / 6) as f64 * 2.5 + 3.0);
            text.push_str(&format!(
                "{{ translate = [{x}, 0.6, {z}], rotate_deg = [0, {}, 0], scale = {} }},\n",
                k * 37,
                0.3 + 0.02 * k as f64
            ));
        }
        // One beside the eye, across its plane.
        text.push_str("{ translate = [1.1, 2, 9], scale = 0.5 },\n]\n");
        text.push_str(
            r#"
            [[objects]]
            name = "knot"
            generator = { kind = "knot", p = 2, q = 3, segments = 60, sides = 8, tube_radius = 0.28 }
            instances = [
            "#,
        );
        for k in 0..29 {
            let (x, z) = ((k % 6) as f64 * 1.7 - 3.2, -(k / 6) as f64 * 2.5 + 1.8);
            text.push_str(&format!(
                "{{ translate = [{x}, 1.0, {z}], rotate_deg = [{}, 20, 0] }},\n",
                k * 11
            ));
        }
        text.push_str("]\n");
        let mut scene = Scene::parse(&text).expect("scene");
        for object in &mut scene.objects {
            object.origin += origin;
        }
        scene
    }

    fn view(origin: DVec3) -> Camera {
        let eye = origin + DVec3::new(0.3, 2.1, 9.0);
        let mut camera =
            Camera::look_at(Vec3::ZERO, Vec3::new(0.0, -0.1, -1.0), Vec3::Y, 70.0, 96, 64).expect("camera");
        camera.eye = eye;
        camera
    }

    /// Each block's samples from the top-level BVH, nearest first with culling, equal
    /// those of every object traced in turn, bit for bit; and the culling skips most
    /// objects. At the origin and 10⁶ m from it, one and three samples a pixel.
    #[test]
    fn the_top_level_finds_every_objects_nearest_hits() {
        for origin in [DVec3::ZERO, DVec3::new(1e6, 0.0, -1e6)] {
            let scene = crowd(origin);
            let tracer = SceneTracer::new(&scene);
            let camera = view(origin);
            for samples in [1, 3] {
                let grid = SampleGrid::new(&tracer, &camera, samples);
                let (mut traced, mut blocks, mut hits) = (0, 0, 0);
                let whole = Block {
                    x0: 0,
                    y0: 0,
                    width: camera.width,
                    height: camera.height,
                };
                for block in whole.tiles() {
                    let culled = grid.nearest(&tracer, block, ObjectWalk::NearestFirst);
                    let every = grid.nearest(&tracer, block, ObjectWalk::EveryObject);
                    assert_eq!(culled, every, "{block:?}");
                    hits += culled.iter().flatten().count();
                    let mut samples_of = BlockSamples::new(block, grid.n);
                    tracer.placements.nearest_first(&grid.rays(block), |k| {
                        traced += 1;
                        grid.trace(&tracer, k, &mut samples_of);
                        samples_of.farthest()
                    });
                    blocks += 1;
                }
                let objects = scene.objects.len();
                assert!(hits > 0, "nothing hit");
                assert!(
                    traced * 8 < blocks * objects,
                    "{traced} objects traced over {blocks} blocks of {objects} objects"
                );
            }
        }
    }
}
