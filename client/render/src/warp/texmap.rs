//! Perspective texture mapping of the pre-warped image onto the source quad: for each
//! screen pixel the ray through it crosses the source plane at `(u, v)`; the pre-warped
//! texel there is the surface the pixel sees (that is what the pre-warp arranged), at
//! view depth `(h + d) / (D·f)` for the ray direction `D` with `D·forward = 1`. Where
//! the pixel falls between covered and empty texels (a silhouette), the covered share
//! of the bilinear weights is its coverage, and the surface is added as a
//! [`Fragment`], blended by it over what lies behind. Pixels whose footprint lies wholly
//! on surface — most of them — are blended eight at once (`blend_full`), to the bit as
//! one by one.

use glam::Vec3;
use rayon::prelude::*;
use wide::bytemuck::cast;
use wide::{f32x8, i32x8};

use relief_core::camera::Camera;
use relief_core::relief::{ReliefTexture, SourceCamera};

use super::params::WarpParams;
use super::prewarp::{Attributes, NORMAL_SHIFT, PTexel, PrewarpImage, field, lerp_attributes};
use super::{round_small, rows_per_task};
use crate::EMPTY_DEPTH;
use crate::gbuffer::{Fragment, GBuffer, Stored, StoredLanes};
use relief_core::shading::{LANE_INDEX, LANES, set_lanes};

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
    map_lanes::<true>(image, texture, params, depths, object, camera, gbuffer);
}

/// [`map`], blending the pixels whose footprints lie wholly on surface eight at once
/// when `EIGHT_AT_ONCE` (else one by one, as the rest: the tests' reference). Returns
/// how many pixels were blended eight at once.
fn map_lanes<const EIGHT_AT_ONCE: bool>(
    image: &PrewarpImage,
    texture: &ReliefTexture,
    params: &WarpParams,
    depths: Depths,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> usize {
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
        return 0;
    }
    // (The gathers' indices are `i32`, doubled: a larger image, far past any texture's,
    // goes one by one.)
    let gathered = EIGHT_AT_ONCE && image.texels.len() <= MAX_GATHERED;
    let (a_scale, b_scale) = (c.a / c.a.length_squared(), c.b / c.b.length_squared());
    // The ray direction D (`Camera::ray`) is linear in the pixel, so are
    // D·f, D·a/|a|², D·b/|b|²: step them along the row.
    let dots = |d: Vec3| Vec3::new(d.dot(c.f), d.dot(a_scale), d.dot(b_scale));
    let x_step = dots(camera.ray_x_step());
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
    let bands: Vec<(Vec<Fragment>, usize)> = gbuffer
        .bands(y0, y1, 1)
        .into_par_iter()
        .with_min_len(rows_per_task((x1 - x0) as usize))
        .map(|mut pixels| {
            let y = pixels.y0();
            let row = dots(camera.ray(x0 as f32 + 0.5, y as f32 + 0.5));
            let mut blended = 0;
            // Eight pixels at once: most of the rectangle is empty, and a group none of
            // whose footprints holds a texel costs a few vector operations and gathers.
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
                let k = ys * i32x8::splat(image.width as i32) + xs;
                let ks = k.to_array();
                // Where in its footprint each pixel falls.
                let (tx, ty) = (fu - f32x8::from_i32x8(xs), fv - f32x8::from_i32x8(ys));
                // Inside lanes whose four footprint texels all hold surface are blended
                // eight at once (`full`: the bulk of a surface); the silhouette's and the
                // rim's one by one (`single`); footprints wholly empty, not at all.
                let mut single = rim;
                if inside != 0 && !gathered {
                    single |= inside;
                } else if inside != 0 {
                    let step = i32x8::splat(image.width as i32);
                    let at = [k, k + i32x8::splat(1), k + step, k + step + i32x8::splat(1)];
                    let depth = at.map(|at| gather_depths(&image.texels, at));
                    let empty = depth.map(|d| d.simd_eq(f32x8::splat(EMPTY_DEPTH)).to_bitmask());
                    let any_empty = empty[0] | empty[1] | empty[2] | empty[3];
                    let all_empty = empty[0] & empty[1] & empty[2] & empty[3];
                    let full = inside & !any_empty;
                    single |= inside & !all_empty & !full;
                    if full != 0 {
                        let words = at.map(|at| gather_words(&image.texels, at));
                        let (depth, stored) = blend_full(depth, &words, tx, ty, object);
                        let view_depth =
                            (f32x8::splat(params.h) + depth) / towards_plane * f32x8::splat(depths.world);
                        let tested = view_depth * f32x8::splat(depths.tested);
                        pixels.keep_nearer_lanes_as(x, full, tested, view_depth, &stored);
                        blended += full.count_ones() as usize;
                    }
                }
                if single == 0 {
                    continue;
                }
                let (tx, ty, u, v) = (tx.to_array(), ty.to_array(), u.to_array(), v.to_array());
                let towards_plane = towards_plane.to_array();
                for l in set_lanes(single) {
                    let found = if inside & (1 << l) != 0 {
                        sample_inside(image, ks[l] as usize, tx[l], ty[l])
                    } else {
                        image
                            .at(u[l], v[l])
                            .filter(|t| !t.is_empty())
                            .map(|t| (t.depth, t.attributes, 1.0))
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
            (pixels.into_fragments(), blended)
        })
        .collect();
    let blended = bands.iter().map(|(_, n)| n).sum();
    gbuffer.add_fragments(bands.into_iter().flat_map(|(fragments, _)| fragments));
    blended
}

/// The most texels an image may have for [`gather_depths`] and [`gather_words`] to
/// reach each: their indices, doubled (a texel is two 8-byte steps), stay `i32`.
const MAX_GATHERED: usize = (i32::MAX / 2) as usize;

/// The depth of `texels[index[l]]` in lane `l`; an index outside `texels` (a lane not
/// drawn) reads its first or last texel, and an empty `texels` gives empty depths.
#[inline(always)]
fn gather_depths(texels: &[PTexel], index: i32x8) -> f32x8 {
    let Some(index) = within(texels, index) else {
        return f32x8::splat(EMPTY_DEPTH);
    };
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{__m256i, _mm256_i32gather_ps};
        // (In 8-byte steps: a texel is two.)
        let steps: __m256i = cast(index + index);
        // SAFETY: every index lies within `texels` and below `MAX_GATHERED` (`within`),
        // so its step does not overflow; a `PTexel` (`repr(C)`, 16 bytes) holds its
        // depth in its first 4: each lane reads one texel's depth.
        cast(unsafe { _mm256_i32gather_ps::<8>(texels.as_ptr().cast::<f32>(), steps) })
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    f32x8::new(index.to_array().map(|i| texels[i as usize].depth))
}

/// The attribute word of `texels[index[l]]` in lane `l`, as [`gather_depths`] reads
/// (zero from an empty `texels`).
#[inline(always)]
fn gather_words(texels: &[PTexel], index: i32x8) -> [u64; LANES] {
    let Some(index) = within(texels, index) else {
        return [0; LANES];
    };
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{__m128i, __m256i, _mm256_i32gather_epi64};
        let [low, high] = cast::<i32x8, [__m128i; 2]>(index + index + i32x8::splat(1));
        let words = texels.as_ptr().cast::<i64>();
        // SAFETY: as `gather_depths`: the word at the texel's bytes 8..16 is its
        // attributes (`PTexel`'s layout, asserted beside it); each lane reads one.
        let [low, high]: [__m256i; 2] = unsafe {
            [
                _mm256_i32gather_epi64::<8>(words, low),
                _mm256_i32gather_epi64::<8>(words, high),
            ]
        };
        cast([low, high])
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    index.to_array().map(|i| texels[i as usize].attributes.0)
}

/// `index` clamped into `texels`' indices and below [`MAX_GATHERED`]; `None` when
/// `texels` is empty.
#[inline(always)]
fn within(texels: &[PTexel], index: i32x8) -> Option<i32x8> {
    let last = texels.len().checked_sub(1)?.min(MAX_GATHERED - 1) as i32;
    Some(index.max(i32x8::ZERO).min(i32x8::splat(last)))
}

/// [`sample_inside`] of eight footprints all of whose texels hold surface, their
/// corners' depths and attribute words given (top-left, top-right, bottom-left,
/// bottom-right; lanes not drawn may hold anything), at fractions `(tx, ty)`: the same
/// arithmetic lane by lane, so the same depths and bytes. Returns the depths and the
/// surfaces as the buffer stores them ([`Stored::with_encoded_normal`]'s encoding).
#[inline(always)]
fn blend_full(
    depth: [f32x8; 4],
    words: &[[u64; LANES]; 4],
    tx: f32x8,
    ty: f32x8,
    object: u32,
) -> (f32x8, StoredLanes) {
    let lerp = |p: f32x8, q: f32x8, t: f32x8| p + (q - p) * t;
    let blended_depth = lerp(lerp(depth[0], depth[1], tx), lerp(depth[2], depth[3], tx), ty);
    let top = lerp_attributes(&words[0], &words[1], tx);
    let bottom = lerp_attributes(&words[2], &words[3], tx);
    let blended = lerp_attributes(&top, &bottom, ty);
    // The packed bytes: albedo in the low three, the encoded normal in the next three.
    let normal = |byte: u32| field(&blended, NORMAL_SHIFT + 8 * byte, 8);
    let stored = StoredLanes::with_encoded_normal(
        object,
        field(&blended, 0, NORMAL_SHIFT),
        [normal(0), normal(1), normal(2)],
    );
    (blended_depth, stored)
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

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};
    use relief_core::camera::Camera;
    use relief_core::relief::{DepthBits, SourceProjection};
    use relief_core::scene::Scene;
    use relief_trace::bake;

    use wide::i32x8;

    use super::{gather_depths, gather_words, map_lanes};
    use crate::EMPTY_DEPTH;
    use crate::gbuffer::GBuffer;
    use crate::impostor::{Faces, Impostor};
    use crate::warp::Prewarped;
    use crate::warp::prewarp::{Attributes, PTexel, Variant, baked_from};
    use relief_core::shading::LANES;

    /// Pixels blended eight at once get the very depths, bytes and fragments that
    /// blending them one by one gives, bit for bit (the reference takes every pixel one
    /// by one, gathering nothing): a self-occluding knot and a tree of leaves
    /// (silhouettes everywhere), orthographic and perspective, seen from eyes turned
    /// every way, nearer and farther, tested behind the depths they store, over a buffer
    /// another view of the object already fills. Most surface pixels go through the
    /// lanes (fails if they stop being used).
    #[test]
    fn eight_at_once_blend_as_one_by_one() {
        let scene = Scene::load("default").expect("default scene");
        let (mut cases, mut blended, mut shown, mut kept_under, mut fragments_seen) = (0, 0, 0, 0, 0);
        for name in ["knot", "tree"] {
            let (tracer, centre, eye) = baked_from(&scene, name);
            for (projection, depth_bits) in [
                (SourceProjection::Orthographic, DepthBits::Sixteen),
                (SourceProjection::Perspective, DepthBits::Eight),
            ] {
                let texture = bake(&tracer, eye, 96, depth_bits, projection).expect("baked");
                let impostor = Impostor::new(texture).with_faces(Faces::Front);
                for (yaw, pitch, distance) in
                    [(-30.0f32, 5.0f32, 1.0f32), (4.0, -12.0, 0.7), (15.0, 20.0, 1.6)]
                {
                    let turn =
                        Quat::from_rotation_y(yaw.to_radians()) * Quat::from_rotation_x(pitch.to_radians());
                    let moved = centre + turn * (eye - centre) * distance;
                    let camera = Camera::look_at(moved, centre, Vec3::Y, 50.0, 160, 120).expect("camera");
                    // Another view's surface first, in both buffers alike.
                    let mut under = GBuffer::new(camera.width, camera.height);
                    let before = Camera::look_at(eye, centre, Vec3::Y, 50.0, 160, 120).expect("camera");
                    if let Ok(first) = Prewarped::new(Variant::Interleaved, &impostor, &before) {
                        first.draw(&impostor, 1, &camera, &mut under);
                    }
                    // (Tested behind: the depth tested differs from the depth stored.)
                    let Ok(p) =
                        Prewarped::new(Variant::Interleaved, &impostor, &camera).and_then(|p| p.behind(1.02))
                    else {
                        continue;
                    };
                    let draw = |map: fn(_, _, _, _, _, _, &mut GBuffer) -> usize| {
                        let mut gbuffer = under.clone();
                        let n = map(
                            &p.image,
                            &impostor.texture,
                            &p.params,
                            p.depths,
                            0,
                            &camera,
                            &mut gbuffer,
                        );
                        (gbuffer, n)
                    };
                    let ((lanes, n), (single, none)) = (draw(map_lanes::<true>), draw(map_lanes::<false>));
                    assert_eq!(none, 0);
                    let case = format!("{name} {projection:?} yaw {yaw} pitch {pitch} ×{distance}");
                    for y in 0..camera.height {
                        for x in 0..camera.width {
                            let pixel = |g: &GBuffer| g.stored(x, y).map(|(d, s)| (d.to_bits(), s));
                            assert_eq!(pixel(&lanes), pixel(&single), "{case}: pixel {x}, {y}");
                            shown += usize::from(lanes.object_at(x, y) == 0);
                            kept_under += usize::from(lanes.object_at(x, y) == 1);
                        }
                    }
                    let fragments = |g: &GBuffer| g.fragments_of(0).copied().collect::<Vec<_>>();
                    assert!(fragments(&lanes) == fragments(&single), "{case}: fragments");
                    fragments_seen += fragments(&lanes).len();
                    cases += 1;
                    blended += n;
                }
            }
        }
        assert!(cases >= 10, "{cases} cases");
        // Both surfaces show somewhere, and silhouettes leave fragments.
        assert!(
            shown > 0 && kept_under > 0 && fragments_seen > 0,
            "{shown} {kept_under} {fragments_seen}"
        );
        assert!(
            2 * blended > shown,
            "{blended} pixels sent to the lanes, {shown} shown"
        );
    }

    /// The gathers read each lane's texel, clamp an index outside the texels to the
    /// first or last, and read nothing from no texels.
    #[test]
    fn gathers_read_each_lanes_texel() {
        let texels: Vec<PTexel> = (0..5u64)
            .map(|i| PTexel {
                depth: i as f32 + 0.5,
                attributes: Attributes(0x0102_0304_0506_0708 * (i + 1)),
            })
            .collect();
        let index = [-3, 0, 1, 4, 5, 100, i32::MIN, i32::MAX];
        let clamped = index.map(|i| texels[i.clamp(0, 4) as usize]);
        let got = (
            gather_depths(&texels, i32x8::new(index)),
            gather_words(&texels, i32x8::new(index)),
        );
        assert_eq!(got.0.to_array(), clamped.map(|t| t.depth));
        assert_eq!(got.1, clamped.map(|t| t.attributes.0));
        let none = (
            gather_depths(&[], i32x8::new(index)),
            gather_words(&[], i32x8::new(index)),
        );
        assert_eq!((none.0.to_array(), none.1), ([EMPTY_DEPTH; LANES], [0; LANES]));
    }
}
