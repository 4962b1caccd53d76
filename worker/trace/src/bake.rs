//! Baking a relief texture: cast one ray per texel (parallel, or from the eye — see
//! [`SourceProjection`]) and record the first surface's albedo, shading normal and quantised
//! depth.

use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;

use relief_core::relief::{
    DepthBits, FacingError, ReliefTexture, SourceCamera, SourceProjection, encode_normal_rgb8,
};
use relief_core::shading::to_rgb8;

use crate::bvh::Ray;
use crate::prefetch::prefetch_lines;
use crate::tiles::par_fill_blocks;
use crate::tracer::ObjectTracer;

/// Why a texture could not be baked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("object `{object}`: {reason}")]
pub struct BakeError {
    pub object: String,
    pub reason: FacingError,
}

#[derive(Clone, Copy, Default)]
struct Texel {
    albedo: [u8; 3],
    normal: [u8; 3],
    depth: u16,
}

/// The relief texture of `target` for `eye`, `size × size` texels in `projection` (see
/// [`relief_core::relief`] for the camera and depth mapping). Runs on the current rayon
/// pool.
pub fn bake(
    target: &ObjectTracer,
    eye: Vec3,
    size: u32,
    depth_bits: DepthBits,
    projection: SourceProjection,
) -> Result<ReliefTexture, BakeError> {
    match bake_unless_cancelled(target, eye, size, depth_bits, projection, &AtomicBool::new(false))? {
        Some(texture) => Ok(texture),
        None => unreachable!("a bake nobody can cancel was cancelled"),
    }
}

/// [`bake`], giving up (`Ok(None)`) once `cancelled` is set: it is read before each
/// 8×8 block of rays, so a withdrawn job frees the worker's cores within a block's
/// work instead of a whole texture's.
pub fn bake_unless_cancelled(
    target: &ObjectTracer,
    eye: Vec3,
    size: u32,
    depth_bits: DepthBits,
    projection: SourceProjection,
    cancelled: &AtomicBool,
) -> Result<Option<ReliefTexture>, BakeError> {
    let camera =
        SourceCamera::facing(eye, &target.object.bounds, size, size, projection).map_err(|reason| {
            BakeError {
                object: target.object.name.clone(),
                reason,
            }
        })?;
    let mesh = &target.object.mesh;
    let span = camera.depth_far - camera.depth_near;
    // The plane touches the bounds; start a little before it so surfaces lying in it
    // are not lost to rounding.
    let margin = span * 1e-4;
    let empty = Texel {
        albedo: [0; 3],
        normal: [0; 3],
        depth: depth_bits.empty(),
    };
    let mut texels = vec![empty; size as usize * size as usize];
    par_fill_blocks(size, size, &mut texels, |block, values| {
        if cancelled.load(Ordering::Relaxed) {
            values.resize((block.width * block.height) as usize, empty);
            return;
        }
        let rays: Vec<Ray> = block
            .pixels()
            .map(|(i, j)| {
                // (The direction's component along `f` is 1: `t` is the displacement.)
                let (origin, direction) = camera.texel_ray(i, j);
                Ray {
                    origin,
                    direction,
                    t_min: -margin,
                    t_max: span + margin,
                }
            })
            .collect();
        let mut hits = vec![None; rays.len()];
        target.bvh.intersect_batch(&rays, &mut hits);
        // Shading reads each hit's vertex indices, then its vertices' attributes: fetch
        // both for the whole block before using any (see `prefetch`).
        for hit in hits.iter().flatten() {
            prefetch_lines(std::slice::from_ref(&mesh.triangles[hit.triangle as usize]));
        }
        if let Some(normals) = &mesh.normals {
            for hit in hits.iter().flatten() {
                for &v in &mesh.triangles[hit.triangle as usize] {
                    prefetch_lines(std::slice::from_ref(&normals[v as usize]));
                }
            }
        }
        values.extend(hits.into_iter().map(|hit| match hit {
            None => empty,
            Some(hit) => {
                let tri = hit.triangle as usize;
                Texel {
                    albedo: to_rgb8(mesh.albedo(tri, hit.u, hit.v)),
                    normal: encode_normal_rgb8(mesh.shading_normal(tri, hit.u, hit.v)),
                    depth: camera.level_of_depth(camera.depth_near + hit.t, depth_bits),
                }
            }
        }));
    });
    if cancelled.load(Ordering::Relaxed) {
        return Ok(None);
    }
    let mut texture = ReliefTexture::empty(camera, depth_bits, eye);
    for (k, t) in texels.into_iter().enumerate() {
        texture.albedo[k] = t.albedo;
        texture.normal[k] = t.normal;
        texture.depth[k] = t.depth;
    }
    Ok(Some(texture))
}
