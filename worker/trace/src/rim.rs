//! A rim texel's depth: where its surface meets the outline, not where its centre ray
//! happens to strike.
//!
//! A texel's depth is its centre ray's. Along a grazing rim that samples the depth where
//! it changes fastest: on a sphere of radius `r` texels, a ray `δ` texels inside the
//! outline strikes `√(2rδ)` texels of depth in front of it, so along the rim the stored
//! depths scatter over `√(2r)` texels, as the outline happens to cross each rim texel.
//! A view turned by `θ` moves a texel by its depth times `tan θ`: the scatter became an
//! outline toothed a pixel or two deep on the side the eye turned to (the sphere's
//! texture, 128 texels, turned 17° along its columns: 0.9 dB below exact geometry's
//! score over its own pixels, where turned along its rows it scored 1.5 dB above).
//!
//! So a rim texel (covered, beside an uncovered texel or the texture's edge) casts one
//! more ray towards each uncovered side ([`RIM_RAY_OFFSETS`]), each finding the nearest
//! surface from the texel's own depth on, and takes the deepest that is still its own
//! surface: joined to it as the client's impostor joins neighbours (within the depth its
//! normal's slope reaches: [`relief_core::joins`]), its normal within
//! [`RIM_MAX_TURN_DEG`] of the texel's. Near the outline a smooth rim's depth scatters
//! far less. Its albedo and normal stay its centre's.
//!
//! The cost: the rim lands nearer the texture's own outline, where centre rays' shallow
//! depths had carried some of it out into the band a turned eye sees past it (the band
//! `relief_render::validity::rim` predicts); turned 10°, the sphere scores up to
//! 0.3 dB lower, and the knot within 0.1 dB.

use glam::Vec3;
use rayon::prelude::*;

use relief_core::joins::{join_reach, slope_along};
use relief_core::relief::{ReliefTexture, SourceCamera, TEXEL_SIDES, decode_normal_rgb8};

use crate::bvh::{Hit, Ray};
use crate::tracer::ObjectTracer;

/// Where a rim texel's ray towards an uncovered neighbour crosses the image plane, in
/// texels from its centre: first 0.4 (short of half a texel: what lies further is the
/// neighbour's to sample), then, where that finds nothing of the texel's surface (its
/// outline lies nearer), 0.2.
pub const RIM_RAY_OFFSETS: [f32; 2] = [0.4, 0.2];

/// How far the surface's normal may turn between a rim texel's centre and a rim ray's
/// hit for the hit to count as the same surface. (Along a smooth rim it turns by under
/// `√(2/r)` radians for a rim `r` texels round: 11° on a sphere 58 texels round, 36° on a
/// tube of 5. A surface behind the rim, seen through the gap, faces the eye: 90° off.)
pub const RIM_MAX_TURN_DEG: f32 = 45.0;

/// The deepest a rim ray `offset` texels from its texel's centre may strike and still be
/// joined to the texel, whose depth is `centre_depth` and whose surface rises `slope`
/// along the ray's side ([`join_reach`], as the impostor joins neighbours), texels being
/// `width` wide that way at the image plane. A perspective texture's texels widen with
/// depth, and the reach with them: the bound is where the two meet, and unbounded where
/// they never do.
fn deepest_joined(
    camera: &SourceCamera,
    centre_depth: f32,
    slope: f32,
    width: f32,
    offset: f32,
    quantum: f32,
) -> f32 {
    // (join_reach(slope, step, q) = g·step + 2q, the step `offset·width` at the plane.)
    let g = join_reach(slope, 1.0, 0.0) * offset * width;
    match camera.centre_distance() {
        // (depth − centre ≤ g·(h + depth)/h + 2q.)
        Some(h) if g < h => (centre_depth + g + 2.0 * quantum) / (1.0 - g / h),
        Some(_) => f32::INFINITY,
        None => centre_depth + g + 2.0 * quantum,
    }
}

/// The rim texels of a `w × h` texture of depths `depth`: each covered texel with an
/// uncovered neighbour (or the texture's edge) on some side, and those sides as bits (bit
/// `s` for [`TEXEL_SIDES`]`[s]`). (Over a bordered mask, a row at a time, so that the test
/// runs on whole vectors: texel by texel, it cost as much as tracing the rim rays.)
pub(crate) fn open_sides(depth: &[u16], w: usize, h: usize, empty: u16) -> Vec<(usize, u8)> {
    let stride = w + 2;
    let mut covered = vec![0u8; stride * (h + 2)];
    for (row, depths) in covered[stride..].chunks_mut(stride).zip(depth.chunks(w)) {
        for (c, &q) in row[1..=w].iter_mut().zip(depths) {
            *c = u8::from(q != empty);
        }
    }
    let mut open = vec![0u8; w];
    let mut rims = Vec::new();
    for j in 0..h {
        let [up, here, down] = [j, j + 1, j + 2].map(|r| &covered[r * stride..(r + 1) * stride]);
        for (i, o) in open.iter_mut().enumerate() {
            let c = here[i + 1];
            *o = c * ((1 - here[i]) | (1 - here[i + 2]) << 1 | (1 - up[i + 1]) << 2 | (1 - down[i + 1]) << 3);
        }
        rims.extend(
            open.iter()
                .enumerate()
                .filter(|(_, o)| **o != 0)
                .map(|(i, &o)| (j * w + i, o)),
        );
    }
    rims
}

/// Rim rays are cast in chunks of this many on the thread pool: a chunk is a few
/// hundred microseconds of tracing. No more than one chunk's stay on the calling
/// thread, where they need no hand-over.
const RAYS_PER_TASK: usize = 512;

/// The closest hit of each of `rays` against `target`, in chunks of [`RAYS_PER_TASK`]
/// on the thread pool when `parallel` and there are more than one chunk's (the rim's
/// rays and [`crate::hidden`]'s).
pub(crate) fn cast_rays(target: &ObjectTracer, rays: &[Ray], parallel: bool) -> Vec<Option<Hit>> {
    let mut hits: Vec<Option<Hit>> = vec![None; rays.len()];
    if parallel && rays.len() > RAYS_PER_TASK {
        (rays
            .par_chunks(RAYS_PER_TASK)
            .zip(hits.par_chunks_mut(RAYS_PER_TASK)))
        .for_each(|(rays, hits)| target.bvh.intersect_batch(rays, hits));
    } else {
        target.bvh.intersect_batch(rays, &mut hits);
    }
    hits
}

/// One open side of a rim texel, as its rays need it: the texel, the side (a [`TEXEL_SIDES`]
/// index), the texel's depth and normal, and its surface's slope and its texels' width
/// that way.
#[derive(Clone, Copy)]
struct RimSide {
    texel: usize,
    side: usize,
    centre_depth: f32,
    normal: Vec3,
    slope: f32,
    width: f32,
}

/// Gives each rim texel of `texture` the deepest depth its rim rays find on its own
/// surface (see the module docs). `target` is the texture's object; rays search
/// displacements `t_range` from the texture's near depth, as the bake's own rays do; on
/// the thread pool when `parallel` (as the bake itself: see
/// [`SEQUENTIAL_MAX_EDGE`](crate::bake::SEQUENTIAL_MAX_EDGE)) and there are more than
/// [`RAYS_PER_TASK`] of them.
pub(crate) fn deepen_rims(
    texture: &mut ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    parallel: bool,
) {
    let camera = texture.camera;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let bits = texture.depth_bits;
    let quantum = camera.depth_quantum(bits);
    let min_cos = RIM_MAX_TURN_DEG.to_radians().cos();
    // Every open side of every rim texel, to be tried at the first offset.
    let mut pending: Vec<RimSide> = open_sides(&texture.depth, w, h, bits.empty())
        .into_iter()
        .flat_map(|(k, open)| {
            (0..TEXEL_SIDES.len())
                .filter(move |s| open & (1 << s) != 0)
                .map(move |s| (k, s))
        })
        .map(|(texel, side)| {
            // (Along the side's own axis, as the impostor joins: a texture's texels
            // need not be square.)
            let across = if TEXEL_SIDES[side].0 != 0 {
                camera.a
            } else {
                camera.b
            };
            let width = across.length();
            let normal = decode_normal_rgb8(texture.normal[texel]);
            RimSide {
                texel,
                side,
                centre_depth: camera.depth_of_level(texture.depth[texel], bits),
                normal,
                slope: slope_along(normal, across / width, camera.f),
                width,
            }
        })
        .collect();
    let mut found: Vec<(usize, f32)> = Vec::new();
    for offset in RIM_RAY_OFFSETS {
        let deepest: Vec<f32> = (pending.iter())
            .map(|s| deepest_joined(&camera, s.centre_depth, s.slope, s.width, offset, quantum))
            .collect();
        let rays: Vec<Ray> = (pending.iter().zip(&deepest))
            .map(|(s, &deepest)| {
                let (di, dj) = TEXEL_SIDES[s.side];
                let (u, v) = (
                    (s.texel % w) as f32 + 0.5 + di as f32 * offset,
                    (s.texel / w) as f32 + 0.5 + dj as f32 * offset,
                );
                let origin = camera.point(u, v, camera.depth_near);
                // (`point` is linear in depth: one unit of it along the texel's ray.)
                let direction: Vec3 = camera.point(u, v, camera.depth_near + 1.0) - origin;
                // (Searched from a quantum short of the texel's depth to the deepest a
                // hit joins it: a ray grazing the rim crosses many of the hierarchy's
                // boxes, and a whole-depth search took twice as long.)
                Ray {
                    origin,
                    direction,
                    t_min: t_range.0.max(s.centre_depth - camera.depth_near - quantum),
                    t_max: t_range.1.min(deepest - camera.depth_near),
                }
            })
            .collect();
        let hits = cast_rays(target, &rays, parallel);
        let mut missed = Vec::new();
        for ((s, &deepest), hit) in pending.iter().zip(&deepest).zip(&hits) {
            let own = hit
                .map(|hit| (camera.depth_near + hit.t, hit))
                .filter(|&(depth, hit)| {
                    let normal = target
                        .object
                        .mesh
                        .shading_normal(hit.triangle as usize, hit.u, hit.v);
                    depth > s.centre_depth && depth <= deepest && normal.dot(s.normal) >= min_cos
                });
            match own {
                Some((depth, _)) => found.push((s.texel, depth)),
                None => missed.push(*s),
            }
        }
        pending = missed;
    }
    // (Each depth found lies beyond the texel's own: several sides, the deepest.)
    for (k, depth) in found {
        texture.depth[k] = texture.depth[k].max(camera.level_of_depth(depth, bits));
    }
}
