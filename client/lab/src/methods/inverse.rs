//! Inverse relief mapping (Policarpo, ch. 6.5): for each output pixel, march the depth
//! field along the pixel's ray — `steps` linear steps from where the ray enters the
//! texture's box to where it leaves, then binary refinement of the first crossing. The
//! GPU-style alternative the sources argue against on the CPU; measured for comparison.

use glam::Vec3;

use relief_core::bounds::Aabb;
use relief_core::camera::Camera;
use relief_core::relief::decode_normal_rgb8;

use relief_render::gbuffer::{GBuffer, GPixel};
use relief_render::impostor::Impostor;
use relief_render::warp::texmap::volume_rect;
use relief_render::warp::{WarpError, ensure_finite};

/// Binary-search steps after the linear march.
const REFINE: usize = 6;

/// Shows `impostor` by marching its depth field with `steps` linear steps per pixel.
pub fn display(
    impostor: &Impostor,
    steps: usize,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    let texture = &impostor.texture;
    let c = &texture.camera;
    ensure_finite(c, camera.eye_f32())?;
    let (w, h) = (c.width as f32, c.height as f32);
    let far = c.depth_far;
    let (x0, y0, x1, y1) = volume_rect(camera, c);
    let steps = steps.max(1);
    let (a_scale, b_scale) = (c.a / c.a.length_squared(), c.b / c.b.length_squared());
    let rel = camera.eye_f32() - c.origin;
    // The eye in texture coordinates (u, v, d).
    let eye_t = Vec3::new(rel.dot(a_scale), rel.dot(b_scale), rel.dot(c.f));
    let empty = texture.depth_bits.empty();
    let depth_at = |u: f32, v: f32| -> Option<(usize, f32)> {
        if u < 0.0 || v < 0.0 || u >= w || v >= h {
            return None;
        }
        let k = v as usize * c.width as usize + u as usize;
        let q = texture.depth[k];
        (q != empty).then(|| (k, c.depth_of_level(q, texture.depth_bits)))
    };
    // The texture's volume in texture space: [0, w] × [0, h] × [min(near, 0), far] (a
    // texture may start in front of its plane).
    let volume = Aabb {
        min: Vec3::new(0.0, 0.0, c.depth_near.min(0.0)),
        max: Vec3::new(w, h, far),
    };
    for y in y0..y1 {
        for x in x0..x1 {
            // Direction with D·forward = 1, so the ray parameter is the view depth.
            let d = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
            let d = d / d.dot(camera.forward);
            let dir = Vec3::new(d.dot(a_scale), d.dot(b_scale), d.dot(c.f));
            let Some((t0, t1)) = volume
                .ray_interval(eye_t, dir.recip(), 0.0, f32::INFINITY)
                .filter(|(t0, t1)| t0 < t1)
            else {
                continue;
            };
            let below = |t: f32| {
                let p = eye_t + dir * t;
                depth_at(p.x, p.y).is_some_and(|(_, surface)| p.z >= surface)
            };
            let mut hit = None;
            let mut previous = t0;
            for k in 1..=steps {
                let t = t0 + (t1 - t0) * k as f32 / steps as f32;
                if below(t) {
                    let (mut lo, mut hi) = (previous, t);
                    for _ in 0..REFINE {
                        let mid = 0.5 * (lo + hi);
                        if below(mid) { hi = mid } else { lo = mid }
                    }
                    hit = Some(hi);
                    break;
                }
                previous = t;
            }
            let Some(t) = hit else { continue };
            let p = eye_t + dir * t;
            let Some((k, surface)) = depth_at(p.x, p.y) else {
                continue;
            };
            // The surface point's view depth: back along the ray to the texel's depth.
            let depth = if dir.z.abs() > 1e-12 {
                t - (p.z - surface) / dir.z
            } else {
                t
            };
            gbuffer.write(
                x as i64,
                y as i64,
                GPixel {
                    depth,
                    object,
                    albedo: texture.albedo[k],
                    normal: decode_normal_rgb8(texture.normal[k]),
                },
            );
        }
    }
    Ok(())
}
