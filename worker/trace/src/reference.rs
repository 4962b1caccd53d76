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

use crate::bvh::Ray;
use crate::tiles::par_fill_blocks;
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
    let offsets: Vec<(f32, f32)> = (0..n)
        .flat_map(|j| (0..n).map(move |i| ((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32)))
        .collect();
    let background = to_rgb8(tracer.background);
    let mut pixels = vec![(background, NO_OBJECT); camera.width as usize * camera.height as usize];
    par_fill_blocks(camera.width, camera.height, &mut pixels, |block, values| {
        let rays: Vec<Ray> = block
            .pixels()
            .flat_map(|(x, y)| {
                offsets.iter().map(move |&(dx, dy)| Ray {
                    origin: camera.eye,
                    direction: camera.ray_direction(x as f32 + dx, y as f32 + dy),
                    t_min: 0.0,
                    t_max: f32::INFINITY,
                })
            })
            .collect();
        let mut hits = vec![None; rays.len()];
        tracer.closest_hits(&rays, &mut hits);
        // Every hit lit at once (the model runs several points per instruction).
        let points: Vec<SurfacePoint> = rays
            .iter()
            .zip(&hits)
            .filter_map(|(ray, hit)| {
                let (k, hit) = hit.as_ref()?;
                let o = &tracer.objects[*k].object;
                let tri = hit.triangle as usize;
                Some(SurfacePoint {
                    albedo: o.mesh.albedo(tri, hit.u, hit.v),
                    normal: o.mesh.shading_normal(tri, hit.u, hit.v),
                    position: ray.origin + ray.direction * hit.t,
                    towards_eye: -ray.direction,
                    specular: o.specular,
                })
            })
            .collect();
        let mut lit = vec![Vec3::ZERO; points.len()];
        tracer.lighting.shade_all(&points, &mut lit);
        let mut lit = lit.into_iter();
        let shaded: Vec<(Vec3, u32)> = hits
            .iter()
            .map(|hit| match hit {
                None => (tracer.background, NO_OBJECT),
                Some((k, _)) => (lit.next().unwrap_or(tracer.background), *k as u32),
            })
            .collect();
        values.extend(shaded.chunks_exact(offsets.len()).map(|pixel| {
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
