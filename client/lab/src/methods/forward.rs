//! Forward warping: every texel's surface point projected straight to the screen as a
//! point (a z-tested splat into a layer over the impostor's screen rectangle), holes
//! filled by [`super::pullpush`], then the layer merged into the frame.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::relief::decode_normal_rgb8;

use super::pullpush::{DepthMargin, Layer, Pixel, Splat, fill};
use relief_render::gbuffer::{GBuffer, GPixel};
use relief_render::impostor::Impostor;
use relief_render::warp::texmap::volume_rect;
use relief_render::warp::{WarpError, ensure_finite};

/// Largest splat radius in pixels (a texture this coarse for the screen needs a finer
/// one: see the resolution test).
const MAX_SPLAT_RADIUS: f32 = 6.0;

/// A texel projected to the screen: position in layer coordinates, view depth, and the
/// radius of the disc it must cover (half the distance to its farthest connected
/// neighbour, plus half a pixel).
#[derive(Debug, Clone, Copy)]
struct Point {
    at: glam::Vec2,
    depth: f32,
    radius: f32,
    texel: usize,
}

/// Every texel projected into a layer over the screen rectangle the texture can cover.
struct Projection {
    x0: u32,
    y0: u32,
    width: usize,
    height: usize,
    points: Vec<Point>,
}

fn project(impostor: &Impostor, camera: &Camera) -> Result<Option<Projection>, WarpError> {
    let texture = &impostor.texture;
    let c = &texture.camera;
    ensure_finite(c, camera.eye_f32())?;
    let far = c.depth_far;
    let (x0, y0, x1, y1) = volume_rect(camera, c);
    if x1 <= x0 || y1 <= y0 {
        return Ok(None);
    }
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
    let mut projected: Vec<Option<(glam::Vec2, f32)>> = vec![None; tw * th];
    let projection = camera.projection();
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
            let (px, py) = projection.view_to_pixel(p);
            let at = glam::Vec2::new(px - x0 as f32, py - y0 as f32);
            if at.is_finite() {
                projected[k] = Some((at, p.z));
            }
        }
    }
    let mut points = Vec::with_capacity(tw * th);
    for j in 0..th {
        for i in 0..tw {
            let k = j * tw + i;
            let Some((at, depth)) = projected[k] else {
                continue;
            };
            // Connected neighbours only: across a discontinuity the gap is a
            // disocclusion, not a sampling hole.
            let neighbours = [
                (i + 1 < tw && impostor.right[k]).then(|| k + 1),
                (i > 0 && impostor.right[k - 1]).then(|| k - 1),
                (j + 1 < th && impostor.down[k]).then(|| k + tw),
                (j > 0 && impostor.down[k - tw]).then(|| k - tw),
            ];
            let reach = neighbours
                .into_iter()
                .flatten()
                .filter_map(|n| projected[n])
                .map(|(p, _)| p.distance(at))
                .fold(0f32, f32::max);
            points.push(Point {
                at,
                depth,
                radius: (0.5 * reach).min(MAX_SPLAT_RADIUS) + 0.5,
                texel: k,
            });
        }
    }
    Ok(Some(Projection {
        x0,
        y0,
        width: (x1 - x0) as usize,
        height: (y1 - y0) as usize,
        points,
    }))
}

fn splat_of(impostor: &Impostor, p: &Point) -> Splat {
    Splat {
        depth: p.depth,
        albedo: impostor.texture.albedo[p.texel],
        normal: impostor.texture.normal[p.texel],
    }
}

/// Writes the valid pixels of `layer` at `(x0, y0)` into the frame.
fn merge(layer: &Layer, keep: impl Fn(usize) -> bool, x0: u32, y0: u32, object: u32, gbuffer: &mut GBuffer) {
    for (k, s) in layer.pixels.iter().enumerate() {
        if s.is_valid() && keep(k) {
            let (x, y) = (
                (k % layer.width) as i64 + x0 as i64,
                (k / layer.width) as i64 + y0 as i64,
            );
            gbuffer.write(
                x,
                y,
                GPixel {
                    depth: s.depth,
                    object,
                    albedo: s.albedo,
                    normal: decode_normal_rgb8(s.normal),
                },
            );
        }
    }
}

/// One surface spans about its footprint in depth (more on slopes): three footprints of
/// a level's pixel, plus two texels.
fn surface_margin(impostor: &Impostor, camera: &Camera) -> impl Fn(usize) -> DepthMargin {
    let focal = camera.focal_pixels();
    let c = &impostor.texture.camera;
    let texel = c.a.length().max(c.b.length());
    move |level| DepthMargin {
        per_depth: 3.0 * (1u32 << level) as f32 / focal,
        constant: 2.0 * texel,
    }
}

/// Forward-warps `impostor` to `camera`, fills holes by pull–push, writes into
/// `gbuffer`.
pub fn display(
    impostor: &Impostor,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    let Some(projection) = project(impostor, camera)? else {
        return Ok(());
    };
    let (lw, lh) = (projection.width, projection.height);
    let mut layer = Layer::new(lw, lh);
    // Splat each texel into the pixel it lands in, and mark the disc it covers.
    let mut coverage = vec![false; lw * lh];
    let mut widest = 0f32;
    for p in &projection.points {
        let (lx, ly) = (p.at.x.floor(), p.at.y.floor());
        if lx >= 0.0 && ly >= 0.0 && lx < lw as f32 && ly < lh as f32 {
            let slot = &mut layer.pixels[ly as usize * lw + lx as usize];
            if p.depth < slot.depth {
                *slot = splat_of(impostor, p);
            }
        }
        widest = widest.max(p.radius);
        let r = p.radius;
        let (cx0, cx1) = (
            (p.at.x - r).floor().max(0.0) as usize,
            ((p.at.x + r).ceil().max(0.0) as usize).min(lw),
        );
        let (cy0, cy1) = (
            (p.at.y - r).floor().max(0.0) as usize,
            ((p.at.y + r).ceil().max(0.0) as usize).min(lh),
        );
        for y in cy0..cy1 {
            for x in cx0..cx1 {
                if glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5).distance_squared(p.at) <= r * r {
                    coverage[y * lw + x] = true;
                }
            }
        }
    }
    if widest == 0.0 {
        return Ok(());
    }
    let levels = ((2.0 * widest).log2().ceil().max(0.0) as usize + 1).min(8);
    fill(&mut layer, levels, surface_margin(impostor, camera));
    merge(
        &layer,
        |k| coverage[k],
        projection.x0,
        projection.y0,
        object,
        gbuffer,
    );
    Ok(())
}

/// Forward-warps `impostor` and reconstructs with the `k × k` kernel of Marroquim
/// ch. 6: each point is stored at the pyramid level `ceil(log2(D / k))` for its screen
/// diameter `D`; each pixel gathers, at every level, the points in the `k × k` cells
/// around it that cover it, weighted `1 − d` (d their distance over their radius), and
/// averages the front-most group.
pub fn display_kernel(
    impostor: &Impostor,
    k: usize,
    object: u32,
    camera: &Camera,
    gbuffer: &mut GBuffer,
) -> Result<(), WarpError> {
    let Some(projection) = project(impostor, camera)? else {
        return Ok(());
    };
    let (lw, lh) = (projection.width, projection.height);
    let k = k.max(1) | 1;
    const LEVELS: usize = 6;
    // Per level, the nearest point in each cell (index into `points`).
    let mut grids: Vec<(usize, usize, Vec<u32>)> = (0..LEVELS)
        .map(|l| {
            let (w, h) = (lw.div_ceil(1 << l), lh.div_ceil(1 << l));
            (w, h, vec![u32::MAX; w * h])
        })
        .collect();
    let points = &projection.points;
    for (n, p) in points.iter().enumerate() {
        let level = ((2.0 * p.radius / k as f32).log2().ceil().max(0.0) as usize).min(LEVELS - 1);
        let (gw, gh, cells) = &mut grids[level];
        let (cx, cy) = (p.at.x / (1 << level) as f32, p.at.y / (1 << level) as f32);
        if cx < 0.0 || cy < 0.0 || cx >= *gw as f32 || cy >= *gh as f32 {
            continue;
        }
        let slot = &mut cells[cy as usize * *gw + cx as usize];
        if *slot == u32::MAX || p.depth < points[*slot as usize].depth {
            *slot = n as u32;
        }
    }
    let margin = surface_margin(impostor, camera);
    let half = (k / 2) as i64;
    let mut layer = Layer::new(lw, lh);
    let mut candidates: Vec<(f32, Splat)> = Vec::new();
    for y in 0..lh {
        for x in 0..lw {
            let centre = glam::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            candidates.clear();
            for (level, (gw, gh, cells)) in grids.iter().enumerate() {
                let (cx, cy) = ((x >> level) as i64, (y >> level) as i64);
                for dy in -half..=half {
                    for dx in -half..=half {
                        let (qx, qy) = (cx + dx, cy + dy);
                        if qx < 0 || qy < 0 || qx >= *gw as i64 || qy >= *gh as i64 {
                            continue;
                        }
                        let n = cells[qy as usize * gw + qx as usize];
                        if n == u32::MAX {
                            continue;
                        }
                        let p = &points[n as usize];
                        let d = p.at.distance(centre) / p.radius;
                        if d < 1.0 {
                            candidates.push((1.0 - d, splat_of(impostor, p)));
                        }
                    }
                }
            }
            if !candidates.is_empty() {
                let average = super::pullpush::front_average(&candidates, margin(0));
                layer.pixels[y * lw + x] = Splat::from_lanes(average);
            }
        }
    }
    merge(&layer, |_| true, projection.x0, projection.y0, object, gbuffer);
    Ok(())
}
