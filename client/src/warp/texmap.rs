//! Perspective texture mapping of the pre-warped image onto the source quad: for each
//! screen pixel the ray through it crosses the source plane at `(u, v)`; the pre-warped
//! texel there is the surface the pixel sees (that is what the pre-warp arranged), at
//! view depth `(h + d) / (D·f)` for the ray direction `D` with `D·forward = 1`.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use super::params::WarpParams;
use super::prewarp::PrewarpImage;
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
        let y = pixels.y0;
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
            let Some((depth, albedo, normal)) = sample(image, u, v) else {
                continue;
            };
            pixels.keep_nearer_stored(
                x,
                (params.h + depth) / towards_plane,
                &Stored::new(object, albedo, normal),
            );
        }
    });
}

/// The pre-warped image at plane coordinates `(u, v)`: bilinear where the four nearest
/// texels are all covered (inside a surface), nearest at silhouettes (blending with
/// empty texels would invent colours). Returns `(depth, albedo, normal)`, the normal
/// of length 1 or less: a blend of unit normals, left for the shading to normalise
/// (vectorised there, per pixel here).
#[inline]
fn sample(image: &PrewarpImage, u: f32, v: f32) -> Option<(f32, [u8; 3], Vec3)> {
    let fu = u - 0.5 - image.u0 as f32;
    let fv = v - 0.5 - image.v0 as f32;
    let (x, y) = (fu.floor(), fv.floor());
    let (tx, ty) = (fu - x, fv - y);
    let (x, y) = (x as i64, y as i64);
    let (w, h) = (image.width as i64, image.height as i64);
    if x >= 0 && y >= 0 && x + 1 < w && y + 1 < h {
        let k = y as usize * w as usize + x as usize;
        let quad = [
            &image.texels[k],
            &image.texels[k + 1],
            &image.texels[k + w as usize],
            &image.texels[k + w as usize + 1],
        ];
        if quad.iter().all(|t| !t.is_empty()) {
            let weights = [(1.0 - tx) * (1.0 - ty), tx * (1.0 - ty), (1.0 - tx) * ty, tx * ty];
            let (mut depth, mut albedo, mut normal) = (0.0, Vec3::ZERO, Vec3::ZERO);
            let rgb = |c: [u8; 3]| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
            for (t, wgt) in quad.iter().zip(weights) {
                depth += wgt * t.depth;
                albedo += wgt * rgb(t.albedo);
                // Encoded normals blend linearly; one decode (normalisation) after.
                normal += wgt * rgb(t.normal);
            }
            let a = (albedo + Vec3::splat(0.5))
                .to_array()
                .map(|c| c.clamp(0.0, 255.0) as u8);
            return Some((depth, a, normal / 127.5 - Vec3::ONE));
        }
    }
    let texel = image.at(u, v)?;
    let rgb = Vec3::from(texel.normal.map(f32::from));
    (!texel.is_empty()).then(|| (texel.depth, texel.albedo, rgb / 127.5 - Vec3::ONE))
}
