//! Perspective texture mapping of the pre-warped image onto the source quad: for each
//! screen pixel the ray through it crosses the source plane at `(u, v)`; the pre-warped
//! texel there is the surface the pixel sees (that is what the pre-warp arranged), at
//! view depth `(h + d) / (D·f)` for the ray direction `D` with `D·forward = 1`.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use super::params::WarpParams;
use super::prewarp::{Attributes, PrewarpImage};
use super::round_small;
use crate::gbuffer::{GBuffer, Stored};

/// The screen rectangle `[x0, x1) × [y0, y1)` that the plane region `corners` can
/// cover; the whole screen when part of it is behind the eye.
pub(crate) fn screen_rect(camera: &Camera, corners: &[Vec3]) -> (u32, u32, u32, u32) {
    let full = (0, 0, camera.width, camera.height);
    let mut lo = glam::Vec2::splat(f32::INFINITY);
    let mut hi = glam::Vec2::splat(f32::NEG_INFINITY);
    for &p in corners {
        let v = camera.to_view(p);
        if v.z.is_nan() || v.z <= 0.0 {
            return full;
        }
        let (x, y) = camera.view_to_pixel(v);
        lo = lo.min(glam::Vec2::new(x, y));
        hi = hi.max(glam::Vec2::new(x, y));
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return full;
    }
    let clamp_x = |x: f32| x.clamp(0.0, camera.width as f32) as u32;
    let clamp_y = |y: f32| y.clamp(0.0, camera.height as f32) as u32;
    (
        clamp_x(lo.x.floor()),
        clamp_y(lo.y.floor()),
        clamp_x(hi.x.ceil() + 1.0),
        clamp_y(hi.y.ceil() + 1.0),
    )
}

/// The screen rectangle `(x0, y0, x1, y1)` the texture's whole volume (its quad swept
/// from `depth_near` to `depth_far`) can cover.
pub fn volume_rect(camera: &Camera, c: &SourceCamera) -> (u32, u32, u32, u32) {
    let (w, h) = (c.width as f32, c.height as f32);
    let corners: Vec<Vec3> = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
        .into_iter()
        .flat_map(|(u, v)| {
            let p = c.origin + c.a * u + c.b * v;
            [p + c.f * c.depth_near, p + c.f * c.depth_far]
        })
        .collect();
    screen_rect(camera, &corners)
}

/// Maps `image` (pre-warped for `camera.eye`) onto the screen into `gbuffer`.
pub fn map(
    image: &PrewarpImage,
    texture: &ReliefTexture,
    params: &WarpParams,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) {
    let c = &texture.camera;
    let plane = |u: f32, v: f32| c.origin + c.a * u + c.b * v;
    let (u0, v0) = (image.u0 as f32, image.v0 as f32);
    let (u1, v1) = (u0 + image.width as f32, v0 + image.height as f32);
    // Pixels the pre-warped image covers that the texture's volume can show: the image
    // reaches past the quad towards the epipole, and its corners' projection can be
    // far larger than the object's.
    let (ix0, iy0, ix1, iy1) = screen_rect(
        camera,
        &[plane(u0, v0), plane(u1, v0), plane(u0, v1), plane(u1, v1)],
    );
    let (vx0, vy0, vx1, vy1) = volume_rect(camera, c);
    // (Capped by the buffer too: `display` takes the camera and the buffer apart.)
    let (x0, y0) = (ix0.max(vx0), iy0.max(vy0));
    let (x1, y1) = (ix1.min(vx1).min(gbuffer.width), iy1.min(vy1).min(gbuffer.height));
    if x0 >= x1 || y0 >= y1 {
        return;
    }
    let tan_half = camera.tan_half_fov();
    let aspect = camera.width as f32 / camera.height as f32;
    let (a_scale, b_scale) = (c.a / c.a.length_squared(), c.b / c.b.length_squared());
    // The ray direction D = forward + right·sx + up·sy is linear in the pixel, so are
    // D·f, D·a/|a|², D·b/|b|²: step them along the row.
    let dots = |d: Vec3| Vec3::new(d.dot(c.f), d.dot(a_scale), d.dot(b_scale));
    let sx_step = 2.0 / camera.width as f32 * tan_half * aspect;
    let x_step = dots(camera.right * sx_step);
    // Rows are independent (each pixel samples the image and depth-tests its own slot):
    // split across cores.
    gbuffer.bands(y0, y1, 1).into_par_iter().for_each(|mut pixels| {
        let y = pixels.y0();
        let sy = (1.0 - 2.0 * (y as f32 + 0.5) / camera.height as f32) * tan_half;
        let sx0 = (2.0 * (x0 as f32 + 0.5) / camera.width as f32 - 1.0) * tan_half * aspect;
        let mut row = dots(camera.forward + camera.right * sx0 + camera.up * sy);
        for x in x0 as usize..x1 as usize {
            let along = row;
            row += x_step;
            let towards_plane = along.x;
            if towards_plane.is_nan() || towards_plane <= 0.0 {
                continue;
            }
            let s = params.h / towards_plane;
            let u = params.epipole.x + s * along.y;
            let v = params.epipole.y + s * along.z;
            let Some((depth, attributes)) = sample(image, u, v) else {
                continue;
            };
            let stored = Stored::with_encoded_normal(object, attributes.albedo(), attributes.normal());
            pixels.keep_nearer_stored(x, (params.h + depth) / towards_plane, &stored);
        }
    });
}

/// The pre-warped image at plane coordinates `(u, v)`: bilinear where the four nearest
/// texels are all covered (inside a surface), nearest at silhouettes (blending with
/// empty texels would invent colours). Returns the depth and the attributes (albedo and
/// the encoded normal, blended: the normal may come out shorter than unit, and the
/// shading normalises it).
#[inline]
fn sample(image: &PrewarpImage, u: f32, v: f32) -> Option<(f32, Attributes)> {
    let fu = u - 0.5 - image.u0 as f32;
    let fv = v - 0.5 - image.v0 as f32;
    let (x, y) = (fu.floor(), fv.floor());
    let (tx, ty) = (fu - x, fv - y);
    let (x, y) = (x as i64, y as i64);
    let (w, h) = (image.width as i64, image.height as i64);
    // (`x < w - 1`, not `x + 1 < w`: an infinite coordinate saturates to i64::MAX.)
    if x >= 0 && y >= 0 && x < w - 1 && y < h - 1 {
        let k = y as usize * w as usize + x as usize;
        let w = w as usize;
        let [a, b, c, d] = [k, k + 1, k + w, k + w + 1].map(|k| image.texels[k]);
        if !(a.is_empty() || b.is_empty() || c.is_empty() || d.is_empty()) {
            let lerp = |p: f32, q: f32, t: f32| p + (q - p) * t;
            let depth = lerp(lerp(a.depth, b.depth, tx), lerp(c.depth, d.depth, tx), ty);
            // (`min`: a NaN fraction must not underflow the lanes.)
            let (sx, sy) = (
                round_small(tx * 256.0).min(256) as u64,
                round_small(ty * 256.0).min(256) as u64,
            );
            let top = a.attributes.lerp(b.attributes, sx);
            let bottom = c.attributes.lerp(d.attributes, sx);
            return Some((depth, top.lerp(bottom, sy)));
        }
    }
    let texel = image.at(u, v)?;
    (!texel.is_empty()).then_some((texel.depth, texel.attributes))
}
