//! Perspective texture mapping of the pre-warped image onto the source quad: for each
//! screen pixel the ray through it crosses the source plane at `(u, v)`; the pre-warped
//! texel there is the surface the pixel sees (that is what the pre-warp arranged), at
//! view depth `(h + d) / (D·f)` for the ray direction `D` with `D·forward = 1`. Where
//! the pixel falls between covered and empty texels (a silhouette), the covered share
//! of the bilinear weights is its coverage, and the surface is added as a
//! [`Fragment`], blended by it over what lies behind.

use glam::Vec3;
use rayon::prelude::*;
use wide::{f32x8, i32x8};

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use super::params::WarpParams;
use super::prewarp::{Attributes, PTexel, PrewarpImage};
use super::{MIN_TASK_PIXELS, round_small, rows_per_task};
use crate::gbuffer::{Fragment, GBuffer, Stored};
use relief_core::shading::{LANE_INDEX, LANES};

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
/// along its rays from `depth_near` to `depth_far`) can cover.
pub fn volume_rect(camera: &Camera, c: &SourceCamera) -> (u32, u32, u32, u32) {
    let (w, h) = (c.width as f32, c.height as f32);
    let corners: Vec<Vec3> = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
        .into_iter()
        .flat_map(|(u, v)| [c.point(u, v, c.depth_near), c.point(u, v, c.depth_far)])
        .collect();
    screen_rect(camera, &corners)
}

/// How a texture mapping's depths go into the buffer: multiplied by `world` into the
/// world's metres ([`Prewarped::in_world`](super::Prewarped::in_world)), then by
/// `tested` for the depth test only ([`Prewarped::behind`](super::Prewarped::behind)).
#[derive(Debug, Clone, Copy)]
pub struct Depths {
    pub tested: f32,
    pub world: f32,
}

/// Maps `image` (pre-warped for `camera.eye`) onto the screen into `gbuffer`, its
/// depths as `depths` says.
pub fn map(
    image: &PrewarpImage,
    texture: &ReliefTexture,
    params: &WarpParams,
    depths: Depths,
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
    let (a_scale, b_scale) = (c.a / c.a.length_squared(), c.b / c.b.length_squared());
    // The ray direction D (`Camera::ray`) is linear in the pixel, so are
    // D·f, D·a/|a|², D·b/|b|²: step them along the row.
    let dots = |d: Vec3| Vec3::new(d.dot(c.f), d.dot(a_scale), d.dot(b_scale));
    let x_step = dots(camera.ray_x_step());
    let footprints = footprints(image);
    // Plane coordinates minus these are the bilinear footprint's corner: the texel
    // centres of `image` lie at `u0 + ½ + k`.
    let (corner_u, corner_v) = (f32x8::splat(u0 + 0.5), f32x8::splat(v0 + 0.5));
    let (last_x, last_y) = (
        f32x8::splat(image.width as f32 - 1.0),
        f32x8::splat(image.height as f32 - 1.0),
    );
    let (u1, v1) = (f32x8::splat(u1), f32x8::splat(v1));
    // Rows are independent (each pixel samples the image and depth-tests its own slot):
    // split across cores, no task below `MIN_TASK_PIXELS` (rayon runs work it does not
    // split on this thread). Silhouette pixels come back as fragments.
    let fragments: Vec<Vec<Fragment>> = gbuffer
        .bands(y0, y1, 1)
        .into_par_iter()
        .with_min_len(rows_per_task((x1 - x0) as usize))
        .map(|mut pixels| {
            let y = pixels.y0();
            let row = dots(camera.ray(x0 as f32 + 0.5, y as f32 + 0.5));
            // Eight pixels at once up to the texel look-ups: most of the rectangle is
            // empty, and a group none of whose footprints holds a texel costs a few vector
            // operations.
            for x in (x0 as usize..x1 as usize).step_by(LANES) {
                let steps = f32x8::splat((x - x0 as usize) as f32) + LANE_INDEX;
                let along = |start: f32, step: f32| f32x8::splat(start) + f32x8::splat(step) * steps;
                let towards_plane = along(row.x, x_step.x);
                let s = f32x8::splat(params.h) / towards_plane;
                let u = f32x8::splat(params.foot.x) + s * along(row.y, x_step.y);
                let v = f32x8::splat(params.foot.y) + s * along(row.z, x_step.z);
                let (fu, fv) = (u - corner_u, v - corner_v);
                // (Every comparison is false for NaN.)
                let facing = towards_plane.simd_gt(f32x8::ZERO);
                let inside = facing
                    & fu.simd_ge(f32x8::ZERO)
                    & fv.simd_ge(f32x8::ZERO)
                    & fu.simd_lt(last_x)
                    & fv.simd_lt(last_y);
                // Within the image but not its footprint: the outermost half texel.
                let rim = facing
                    & !inside
                    & u.simd_ge(f32x8::splat(u0))
                    & v.simd_ge(f32x8::splat(v0))
                    & u.simd_lt(u1)
                    & v.simd_lt(v1);
                let n = LANES.min(x1 as usize - x);
                let lanes_in = (1u32 << n) - 1;
                let (inside, rim) = (inside.to_bitmask() & lanes_in, rim.to_bitmask() & lanes_in);
                if inside | rim == 0 {
                    continue;
                }
                // Exact: the inside lanes are non-negative and below the image's size.
                let (xs, ys) = (fu.trunc_int(), fv.trunc_int());
                let ks = (ys * i32x8::splat(image.width as i32) + xs).to_array();
                let (xs, ys) = (xs.to_array(), ys.to_array());
                let (fu, fv, u, v) = (fu.to_array(), fv.to_array(), u.to_array(), v.to_array());
                let towards_plane = towards_plane.to_array();
                for l in 0..n {
                    let found = if inside & (1 << l) != 0 {
                        let k = ks[l] as usize;
                        if footprints[k] == 0 {
                            continue;
                        }
                        let (tx, ty) = (fu[l] - xs[l] as f32, fv[l] - ys[l] as f32);
                        sample_inside(image, k, tx, ty)
                    } else if rim & (1 << l) != 0 {
                        image
                            .at(u[l], v[l])
                            .filter(|t| !t.is_empty())
                            .map(|t| (t.depth, t.attributes, 1.0))
                    } else {
                        None
                    };
                    let Some((depth, attributes, coverage)) = found else {
                        continue;
                    };
                    let stored =
                        Stored::with_encoded_normal(object, attributes.albedo(), attributes.normal());
                    let view_depth = (params.h + depth) / towards_plane[l] * depths.world;
                    let tested = view_depth * depths.tested;
                    if coverage < 1.0 {
                        pixels.add_fragment(x + l, tested, view_depth, coverage, &stored);
                    } else {
                        pixels.keep_nearer_stored_as(x + l, tested, view_depth, &stored);
                    }
                }
            }
            pixels.into_fragments()
        })
        .collect();
    gbuffer.add_fragments(fragments.into_iter().flatten());
}

/// Per texel `k` of `image` (but the last row and column): whether any of the four
/// texels of the bilinear footprint whose top-left is `k` holds a surface — the one
/// look-up that turns away most of a texture mapping's pixels. Both passes in
/// parallel for a large image: they read the whole pre-warped image (4 MB at 512²)
/// before the mapping can start.
fn footprints(image: &PrewarpImage) -> Vec<u8> {
    // (`max`: chunks must not be empty; an image of no texels yields no rows.)
    let w = (image.width as usize).max(1);
    let filled: Vec<u8> = (image.texels.par_iter().with_min_len(MIN_TASK_PIXELS))
        .map(|t| !t.is_empty() as u8)
        .collect();
    let mut out = vec![0; filled.len()];
    out.par_chunks_exact_mut(w)
        .zip(filled.par_chunks_exact(w))
        .zip(filled.par_chunks_exact(w).skip(1))
        .with_min_len(rows_per_task(w))
        .for_each(|((out, top), bottom)| {
            for x in 0..w.saturating_sub(1) {
                out[x] = top[x] | top[x + 1] | bottom[x] | bottom[x + 1];
            }
        });
    out
}

/// The pre-warped image in the bilinear footprint whose top-left texel is `k`, at
/// fractions `(tx, ty)` of the way to its bottom-right, and the share of the footprint's
/// bilinear weight on covered texels — the pixel's coverage, about, where texels are
/// about as large as pixels. Bilinear where the four texels are all covered (inside a
/// surface); at silhouettes the covered texel of most weight (blending with empty
/// texels would invent colours), to be blended by the coverage. Returns the depth, the
/// attributes (albedo and the encoded normal, blended: the normal may come out shorter
/// than unit, and the shading normalises it) and the coverage.
#[inline]
fn sample_inside(image: &PrewarpImage, k: usize, tx: f32, ty: f32) -> Option<(f32, Attributes, f32)> {
    let w = image.width as usize;
    let (top, bottom) = (&image.texels[k..k + 2], &image.texels[k + w..k + w + 2]);
    let [a, b, c, d] = [top[0], top[1], bottom[0], bottom[1]];
    if a.is_empty() || b.is_empty() || c.is_empty() || d.is_empty() {
        let weights = [(1.0 - tx) * (1.0 - ty), tx * (1.0 - ty), (1.0 - tx) * ty, tx * ty];
        let (coverage, heaviest) = [a, b, c, d]
            .into_iter()
            .zip(weights)
            .filter(|(t, _)| !t.is_empty())
            .fold((0.0, None::<(PTexel, f32)>), |(sum, best), (t, w)| {
                let best = match best {
                    Some((_, bw)) if bw >= w => best,
                    _ => Some((t, w)),
                };
                (sum + w, best)
            });
        return heaviest.map(|(t, _)| (t.depth, t.attributes, coverage.min(1.0)));
    }
    let lerp = |p: f32, q: f32, t: f32| p + (q - p) * t;
    let depth = lerp(lerp(a.depth, b.depth, tx), lerp(c.depth, d.depth, tx), ty);
    // (`min`: the lerp's bound, 256; the fractions here are finite and below 1.)
    let (sx, sy) = (
        round_small(tx * 256.0).min(256) as u64,
        round_small(ty * 256.0).min(256) as u64,
    );
    let top = a.attributes.lerp(b.attributes, sx);
    let bottom = c.attributes.lerp(d.attributes, sx);
    Some((depth, top.lerp(bottom, sy), 1.0))
}
