//! The reference frame: the whole scene ray-traced in perspective and lit per pixel with
//! the shared Phong model — the ground truth of every error measurement.

use relief_core::camera::Camera;
use relief_core::frame::{Frame, NO_OBJECT};
use relief_core::shading::to_rgb8;

use crate::bvh::Ray;
use crate::tiles::par_fill_blocks;
use crate::tracer::SceneTracer;

/// Renders `camera`'s view of the scene. Runs on the current rayon pool.
pub fn render_reference(tracer: &SceneTracer, camera: &Camera) -> Frame {
    let background = to_rgb8(tracer.background);
    let mut pixels = vec![(background, NO_OBJECT); camera.width as usize * camera.height as usize];
    par_fill_blocks(camera.width, camera.height, &mut pixels, |block, values| {
        let rays: Vec<Ray> = block
            .pixels()
            .map(|(x, y)| Ray {
                origin: camera.eye,
                direction: camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5),
                t_min: 0.0,
                t_max: f32::INFINITY,
            })
            .collect();
        let mut hits = vec![None; rays.len()];
        tracer.closest_hits(&rays, &mut hits);
        values.extend(rays.iter().zip(hits).map(|(ray, hit)| match hit {
            None => (background, NO_OBJECT),
            Some((k, hit)) => {
                let o = &tracer.objects[k].object;
                let tri = hit.triangle as usize;
                let color = tracer.lighting.shade(
                    o.mesh.albedo(tri, hit.u, hit.v),
                    o.mesh.shading_normal(tri, hit.u, hit.v),
                    ray.origin + ray.direction * hit.t,
                    camera.eye,
                    o.specular,
                );
                (to_rgb8(color), k as u32)
            }
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
