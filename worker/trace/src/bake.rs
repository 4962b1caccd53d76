//! Baking a relief texture: cast one ray per texel (parallel, or from the eye — see
//! [`SourceProjection`]) and record the first surface's albedo, shading normal and quantised
//! depth. The rays are cast a block at a time as one beam ([`PlaneRays`]). Texels on the
//! object's outline then take the depth where their surface meets it ([`crate::rim`]),
//! and look past it for what it hides ([`crate::hidden`]).

use std::sync::atomic::{AtomicBool, Ordering};

use glam::Vec3;
use rayon::prelude::*;

use relief_core::mesh::Mesh;
use relief_core::relief::{
    DepthBits, FacingError, ReliefTexture, SourceCamera, SourceProjection, encode_normal_rgb8,
};
use relief_core::shading::to_rgb8;

use crate::bvh::{Bvh, Hit, PlaneRays};
use crate::hidden::find_hidden;
use crate::prefetch::prefetch_lines;
use crate::rim::deepen_rims;
use crate::tiles::{Block, TILE, band_blocks};
use crate::tracer::ObjectTracer;

/// Why a texture could not be baked.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("object `{object}`: {reason}")]
pub struct BakeError {
    pub object: String,
    pub reason: FacingError,
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

/// Bakes of at most this edge run on the calling thread: split over the thread pool,
/// a small bake waited behind any big one holding it (a 32² request beside a 1024²
/// bake on a worker: 8–31 ms, against 1–2 ms on one thread), and its few blocks gain
/// little from more cores (on an idle worker a 32² request took 1.0–1.6 ms spread,
/// 0.5–1.9 on one thread).
pub const SEQUENTIAL_MAX_EDGE: u32 = 64;

/// [`bake`], giving up (`Ok(None)`) once `cancelled` is set: it is read before each
/// 8×8 block of rays, so a withdrawn job frees the worker's cores within a block's
/// work instead of a whole texture's. (The rim's rays run once begun: 0.2–2.3 ms
/// of a 128² to 512² bake here, see [`crate::rim`]; so does the look past the rim,
/// [`crate::hidden`], 7–17 % of a bake.)
pub fn bake_unless_cancelled(
    target: &ObjectTracer,
    eye: Vec3,
    size: u32,
    depth_bits: DepthBits,
    projection: SourceProjection,
    cancelled: &AtomicBool,
) -> Result<Option<ReliefTexture>, BakeError> {
    let rays = TexelRays::new(target, eye, size, projection)?;
    let camera = rays.camera;
    let mesh = &target.object.mesh;
    let mut texture = ReliefTexture::empty(camera, depth_bits, eye);
    let width = size as usize;
    // Bands of rows of the three planes, filled in place (on all cores, or for a small
    // bake on this thread): an intermediate image and its copy were a third of a small
    // mesh's bake (allocation and first touch of the pages, mostly).
    let band_rows = width * TILE;
    let fill_band =
        |hits: &mut Vec<_>, (band, (albedo, normal, depth)): (usize, (&mut [_], &mut [_], &mut [u16]))| {
            let mut last = LastTriangle::NONE;
            for block in band_blocks(size, band, depth.len() / width) {
                if cancelled.load(Ordering::Relaxed) {
                    return;
                }
                rays.trace(&target.bvh, block, hits);
                prefetch_shading(mesh, hits);
                for ((i, j), hit) in block.pixels().zip(hits.iter()) {
                    let Some(hit) = hit else { continue };
                    let k = (j - block.y0) as usize * width + i as usize;
                    let tri = hit.triangle as usize;
                    if hit.triangle != last.triangle {
                        last = LastTriangle::of(mesh, hit.triangle);
                    }
                    albedo[k] = last
                        .albedo
                        .unwrap_or_else(|| to_rgb8(mesh.albedo(tri, hit.u, hit.v)));
                    normal[k] = last
                        .normal
                        .unwrap_or_else(|| encode_normal_rgb8(mesh.shading_normal(tri, hit.u, hit.v)));
                    depth[k] = camera.level_of_depth(camera.depth_near + hit.t, depth_bits);
                }
            }
        };
    if size <= SEQUENTIAL_MAX_EDGE {
        let bands = (texture.albedo.chunks_mut(band_rows))
            .zip(texture.normal.chunks_mut(band_rows))
            .zip(texture.depth.chunks_mut(band_rows))
            .map(|((albedo, normal), depth)| (albedo, normal, depth));
        let mut hits = Vec::with_capacity(TILE * TILE);
        bands.enumerate().for_each(|band| fill_band(&mut hits, band));
    } else {
        let bands = (
            texture.albedo.par_chunks_mut(band_rows),
            texture.normal.par_chunks_mut(band_rows),
            texture.depth.par_chunks_mut(band_rows),
        );
        (bands.into_par_iter().enumerate()).for_each_init(|| Vec::with_capacity(TILE * TILE), fill_band);
    }
    if cancelled.load(Ordering::Relaxed) {
        return Ok(None);
    }
    let parallel = size > SEQUENTIAL_MAX_EDGE;
    deepen_rims(&mut texture, target, rays.t_range, parallel);
    find_hidden(&mut texture, target, rays.t_range, projection, parallel);
    Ok(Some(texture))
}

/// The last triangle a band shaded, with its albedo and normal where they are the same
/// all over it (no texture, no vertex normals): the texels it covers after the first
/// then cost a comparison. Texels on one triangle come in runs along a row.
struct LastTriangle {
    triangle: u32,
    albedo: Option<[u8; 3]>,
    normal: Option<[u8; 3]>,
}

impl LastTriangle {
    const NONE: LastTriangle = LastTriangle {
        triangle: u32::MAX,
        albedo: None,
        normal: None,
    };

    fn of(mesh: &Mesh, triangle: u32) -> Self {
        let tri = triangle as usize;
        LastTriangle {
            triangle,
            albedo: mesh.uniform_albedo(tri).map(to_rgb8),
            normal: mesh.uniform_normal(tri).map(encode_normal_rgb8),
        }
    }
}

/// Starts fetching what shading reads for a block's hits: each hit's vertex indices,
/// then its vertices' normals, for the whole block before any is used (see
/// `prefetch`).
fn prefetch_shading(mesh: &Mesh, hits: &[Option<Hit>]) {
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
}

/// The ray casting of a bake alone, without shading: how many texels the object
/// covers. `relief bench raytrace` times it apart from the whole bake (`trace_ms`), as
/// Embree's figure is.
pub fn trace_texels(
    target: &ObjectTracer,
    eye: Vec3,
    size: u32,
    projection: SourceProjection,
) -> Result<usize, BakeError> {
    let rays = TexelRays::new(target, eye, size, projection)?;
    // The bake's bands and blocks, each core with one buffer of hits, as the bake's.
    let bands = (size as usize).div_ceil(TILE);
    let covered = (0..bands)
        .into_par_iter()
        .map_init(
            || Vec::with_capacity(TILE * TILE),
            |hits, band| {
                let band_height = TILE.min(size as usize - band * TILE);
                band_blocks(size, band, band_height)
                    .map(|block| {
                        rays.trace(&target.bvh, block, hits);
                        hits.iter().flatten().count()
                    })
                    .sum::<usize>()
            },
        )
        .sum();
    Ok(covered)
}

/// How far before its image plane (and past its far depth) a texture's rays search, as
/// a share of its depth span: the plane touches the object's bounds, and a surface
/// lying in it must not be lost to rounding.
const PLANE_MARGIN: f32 = 1e-4;

/// A texture's rays, one per texel, traced a block at a time as one beam.
struct TexelRays {
    camera: SourceCamera,
    beam: PlaneRays,
    /// The displacements from the near depth that rays search.
    t_range: (f32, f32),
}

impl TexelRays {
    fn new(
        target: &ObjectTracer,
        eye: Vec3,
        size: u32,
        projection: SourceProjection,
    ) -> Result<Self, BakeError> {
        let error = |reason| BakeError {
            object: target.object.name.clone(),
            reason,
        };
        let camera =
            SourceCamera::facing(eye, &target.object.local_bounds, size, size, projection).map_err(error)?;
        let span = camera.depth_far - camera.depth_near;
        let margin = span * PLANE_MARGIN;
        let (t_min, t_max) = (-margin, span + margin);
        let (origin, a, b, f) = (camera.origin, camera.a, camera.b, camera.f);
        // (Rays start at `depth_near`, 0 for every camera `facing` makes.)
        let start = origin + f * camera.depth_near;
        let beam = match camera.centre {
            None => PlaneRays::parallel(start, a, b, f, t_min, t_max),
            Some(centre) => PlaneRays::from_centre(centre, start, a, b, f, t_min, t_max),
        }
        .ok_or(error(FacingError::OutOfRange(eye)))?;
        Ok(TexelRays {
            camera,
            beam,
            t_range: (t_min, t_max),
        })
    }

    /// The nearest hit of each texel of `block`, in [`Block::pixels`] order, into `hits`.
    fn trace(&self, bvh: &Bvh, block: Block, hits: &mut Vec<Option<Hit>>) {
        hits.clear();
        hits.resize((block.width * block.height) as usize, None);
        bvh.intersect_block(&self.beam, block, hits);
    }
}
