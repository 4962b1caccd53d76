//! Forward warping: every texel's surface point projected straight to the screen as a
//! point (a z-tested splat into a layer over the impostor's screen rectangle), holes
//! filled by [`super::pullpush`], then the layer merged into the frame.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::relief::decode_normal;

use super::WarpError;
use super::pullpush::{Layer, Splat, fill};
use super::texmap::screen_rect;
use crate::gbuffer::{GBuffer, GPixel};
use crate::impostor::Impostor;

/// Largest splat radius in pixels (a texture this coarse for the screen needs a finer
/// one: see the resolution test).
const MAX_SPLAT_RADIUS: f32 = 6.0;

/// Forward-warps `texture` to `camera`, reconstructs, and writes into `gbuffer`.
pub fn display(
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    let texture = &impostor.texture;
    let c = &texture.camera;
    if !camera.eye.is_finite() || !c.origin.is_finite() || !c.a.is_finite() || !c.b.is_finite() {
        return Err(WarpError::NonFinite);
    }
    let (w, h) = (c.width as f32, c.height as f32);
    let corner = |u: f32, v: f32, d: f32| c.origin + c.a * u + c.b * v + c.f * d;
    let far = c.depth_far;
    let corners: Vec<Vec3> = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)]
        .into_iter()
        .flat_map(|(u, v)| [corner(u, v, 0.0), corner(u, v, far)])
        .collect();
    let (x0, y0, x1, y1) = screen_rect(camera, &corners);
    if x1 <= x0 || y1 <= y0 {
        return Ok(());
    }
    let (lw, lh) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let mut layer = Layer::new(lw, lh);
    // View-space position is linear in (u, v, d): base + u·va + v·vb + d·vf.
    let base = camera.to_view(c.origin);
    let axis = |v: Vec3| Vec3::new(v.dot(camera.right), v.dot(camera.up), v.dot(camera.forward));
    let (va, vb, vf) = (axis(c.a), axis(c.b), axis(c.f));
    let depths: Vec<Vec3> = (0..=texture.depth_bits.max_level())
        .map(|q| vf * c.depth_of_level(q, texture.depth_bits))
        .collect();
    let empty = texture.depth_bits.empty();
    let near = 1e-6 * (base.length() + far);
    let (tw, th) = (c.width as usize, c.height as usize);
    // Every texel's screen position (layer coordinates) and view depth.
    let mut projected: Vec<Option<(glam::Vec2, f32)>> = vec![None; tw * th];
    for j in 0..th {
        let row = base + vb * (j as f32 + 0.5);
        for i in 0..tw {
            let k = j * tw + i;
            let q = texture.depth[k];
            if q == empty {
                continue;
            }
            let p = row + va * (i as f32 + 0.5) + depths[q as usize];
            if p.z.is_nan() || p.z <= near {
                continue;
            }
            let (px, py) = camera.view_to_pixel(p);
            let at = glam::Vec2::new(px - x0 as f32, py - y0 as f32);
            if at.is_finite() {
                projected[k] = Some((at, p.z));
            }
        }
    }
    // Splat each texel into the pixel it lands in, and mark the disc it covers: half the
    // distance to its farthest neighbour on screen (so the gaps between neighbours are
    // covered, and nothing past a silhouette is).
    let mut coverage = vec![false; lw * lh];
    let mut widest = 0f32;
    for j in 0..th {
        for i in 0..tw {
            let k = j * tw + i;
            let Some((at, z)) = projected[k] else {
                continue;
            };
            let (lx, ly) = (at.x.floor(), at.y.floor());
            if lx >= 0.0 && ly >= 0.0 && lx < lw as f32 && ly < lh as f32 {
                let slot = &mut layer.pixels[ly as usize * lw + lx as usize];
                if z < slot.depth {
                    let [r, g, b] = texture.albedo[k];
                    *slot = Splat {
                        depth: z,
                        albedo: Vec3::new(r as f32, g as f32, b as f32) / 255.0,
                        normal: decode_normal(texture.normal[k]),
                        valid: true,
                    };
                }
            }
            // Connected neighbours only: across a discontinuity the gap is a
            // disocclusion, not a sampling hole.
            let mut reach = 0f32;
            let neighbours = [
                (i + 1 < tw && impostor.right[k]).then(|| k + 1),
                (i > 0 && impostor.right[k - 1]).then(|| k - 1),
                (j + 1 < th && impostor.down[k]).then(|| k + tw),
                (j > 0 && impostor.down[k - tw]).then(|| k - tw),
            ];
            for n in neighbours.into_iter().flatten() {
                if let Some((p, _)) = projected[n] {
                    reach = reach.max(p.distance(at));
                }
            }
            let radius = (0.5 * reach).min(MAX_SPLAT_RADIUS) + 0.5;
            widest = widest.max(radius);
            let (cx0, cx1) = (
                (at.x - radius).floor().max(0.0),
                (at.x + radius).ceil().min(lw as f32 - 1.0),
            );
            let (cy0, cy1) = (
                (at.y - radius).floor().max(0.0),
                (at.y + radius).ceil().min(lh as f32 - 1.0),
            );
            let mut y = cy0;
            while y <= cy1 {
                let mut x = cx0;
                while x <= cx1 {
                    if glam::Vec2::new(x + 0.5, y + 0.5).distance_squared(at) <= radius * radius {
                        coverage[y as usize * lw + x as usize] = true;
                    }
                    x += 1.0;
                }
                y += 1.0;
            }
        }
    }
    if widest == 0.0 {
        return Ok(());
    }
    let focal = camera.height as f32 / (2.0 * camera.tan_half_fov());
    let texel = c.a.length().max(c.b.length());
    let levels = ((2.0 * widest).log2().ceil().max(0.0) as usize + 1).min(8);
    // One surface spans about its footprint in depth (more on slopes): allow three
    // footprints of a level's pixel, plus two texels.
    fill(&mut layer, levels, |depth, level| {
        3.0 * (1u32 << level) as f32 * depth / focal + 2.0 * texel
    });
    for (k, s) in layer.pixels.iter().enumerate() {
        if s.valid && coverage[k] {
            let (x, y) = ((k % lw) as i64 + x0 as i64, (k / lw) as i64 + y0 as i64);
            gbuffer.write(
                x,
                y,
                GPixel {
                    depth: s.depth,
                    object,
                    albedo: relief_core::shading::to_rgb8(s.albedo),
                    normal: s.normal.normalize_or_zero(),
                },
            );
        }
    }
    Ok(())
}
