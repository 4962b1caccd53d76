//! What a texture's rim hides: the surfaces a turn of the eye uncovers beside its
//! outline ([`Hidden`]).
//!
//! Seen from the side, an animal's far legs stand hidden behind its near ones; a few
//! degrees round they step out beside them. The texture holds no texel of them and its
//! planes no hint that anything is there: the gaps the client predicts from
//! neighbouring depths (`relief_render::validity::critical`) lie between two surfaces
//! the texture shows, and beside a rim there is only sky. So from every other rim
//! texel along the rim, the bake looks inwards, away from each open side, at every
//! [`INWARD_STRIDE`]th texel up to [`inward_reach`] over the object's covered texels:
//! it casts the texel's ray on past its own surface — through the back faces it meets
//! (its own surface's far side), to the first face turned towards the rays. The
//! deepest step goes first, and a step that finds a surface is followed by the next
//! towards the rim, so the walk records the nearest step of the run that reaches the
//! deepest: where the hidden surface lies and how deep, what the client needs to
//! predict how far a turn brings it out. A rim that hides nothing (most of an
//! outline) costs one ray or two. (The client keeps the largest depth step of each
//! region's: one rim texel in two finds it, for half the rays.)
//!
//! What the walk steps over is taken as the rim's own surface: a nearer surface seen
//! beside it would be a step in depth the client measures apart.
//!
//! Only orthographic textures look: a perspective one is a sheet's (leaves, two-sided),
//! whose winding says nothing of which way a face looks.

use rayon::prelude::*;

use relief_core::relief::{Hidden, ReliefTexture, SourceProjection, TEXEL_SIDES};

use crate::bvh::{Hit, Ray};
use crate::rim::open_sides;
use crate::tracer::ObjectTracer;

/// How many faces a ray may cross looking for one that faces it: its own surface's
/// far side, then (on a mesh of shells, or grazing a fold) one more. What lies past
/// that many is left unknown, as if there were nothing.
pub const MAX_CROSSINGS: usize = 3;

/// Texels between the rays cast inwards from a rim texel, and from the rim to the
/// first: a surface found up to this many texels late is predicted to come out as
/// much later (2 pixels or less, at the textures' usual half a pixel a texel). None is
/// cast at the rim texel itself: a surface behind it that reached past it would cover
/// its open neighbour, which would then not be open. (At a stride of 2, from the rim
/// on, a 256² bake took 2–3 times as long.)
pub const INWARD_STRIDE: u8 = 4;

/// How far in from the rim a texture looks for what it hides: a sixteenth of its
/// larger edge (16 texels of a 256² texture, 32 of a 512²). A surface further in comes
/// out only past a turn that moves it that far, by when the gaps' tolerance (24 pixels
/// at most, at about a pixel a texel) has retired the texture.
pub fn inward_reach(width: u32, height: u32) -> u8 {
    (width.max(height) / 16).clamp(1, u32::from(u8::MAX)) as u8
}

/// Rays are cast in chunks of this many on the thread pool (as the rim's are).
const RAYS_PER_TASK: usize = 512;

/// One open side of a rim texel being walked inwards (from the deepest step out).
#[derive(Clone, Copy)]
struct Walk {
    /// The rim texel.
    texel: usize,
    side: u8,
    /// Texels in from it.
    inward: u8,
    /// The nearest step so far that found a hidden surface, and its depth level.
    found: Option<(u8, u16)>,
}

impl Walk {
    /// What the walk found, as the texture lists it.
    fn hidden(&self) -> Option<Hidden> {
        self.found.map(|(inward, depth)| Hidden {
            texel: self.texel as u32,
            side: self.side,
            inward,
            depth,
        })
    }
}

/// Fills `texture.hidden` (see the module docs). `target` is the texture's object;
/// `t_range` the bake's own rays' search from the texture's near depth; on the thread
/// pool when `parallel`.
pub(crate) fn find_hidden(
    texture: &mut ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    projection: SourceProjection,
    parallel: bool,
) {
    if projection != SourceProjection::Orthographic {
        return;
    }
    let camera = texture.camera;
    let (w, h) = (camera.width as usize, camera.height as usize);
    let bits = texture.depth_bits;
    let empty = bits.empty();
    let reach = inward_reach(camera.width, camera.height);
    // The texel `inward` texels in from rim texel `texel` away from `side`, if it is
    // inside the texture and covered.
    let at = |texel: usize, side: u8, inward: u8| -> Option<usize> {
        let (di, dj) = TEXEL_SIDES[side as usize];
        let step = |x: usize, d: i32| x.checked_add_signed(-(d as isize) * inward as isize);
        let (i, j) = (step(texel % w, di)?, step(texel / w, dj)?);
        let k = j * w + i;
        (i < w && j < h && texture.depth[k] != empty).then_some(k)
    };
    // Each walk starts at the deepest step it can take over covered texels (a gap to
    // the sky ends the object's surface there).
    let mut walks: Vec<Walk> = open_sides(&texture.depth, w, h, empty)
        .into_iter()
        .flat_map(|(texel, open)| {
            (0..TEXEL_SIDES.len() as u8)
                .filter(move |s| open & (1 << s) != 0 && every_other(texel, w, *s))
                .map(move |side| (texel, side))
        })
        .filter_map(|(texel, side)| {
            let covered = (1..=reach).take_while(|&k| at(texel, side, k).is_some()).last()?;
            let inward = covered / INWARD_STRIDE * INWARD_STRIDE;
            (inward > 0).then_some(Walk {
                texel,
                side,
                inward,
                found: None,
            })
        })
        .collect();
    // Each step's rays for all walks at once; a walk that finds a surface steps out
    // towards the rim, and ends where it finds none (or at the first step).
    let mut found: Vec<Hidden> = Vec::new();
    while !walks.is_empty() {
        // (Every step of a walk is covered: its first was, and those nearer the rim.)
        let texels: Vec<usize> = (walks.iter())
            .filter_map(|walk| at(walk.texel, walk.side, walk.inward))
            .collect();
        debug_assert_eq!(texels.len(), walks.len());
        let hits = hidden_depths(texture, target, t_range, &texels, parallel);
        let mut onwards = Vec::new();
        for (mut walk, hit) in walks.into_iter().zip(hits) {
            match hit.filter(|&depth| depth > texture.depth[walk.texel]) {
                Some(depth) => {
                    walk.found = Some((walk.inward, depth));
                    match walk.inward.checked_sub(INWARD_STRIDE).filter(|&k| k > 0) {
                        Some(inward) => onwards.push(Walk { inward, ..walk }),
                        None => found.extend(walk.hidden()),
                    }
                }
                None => found.extend(walk.hidden()),
            }
        }
        walks = onwards;
    }
    found.sort_unstable_by_key(Hidden::key);
    texture.hidden = found;
}

/// For each of `texels` of `texture`, the depth level of the first face behind its
/// own surface that faces the rays: its ray cast on from just past its depth (a surface
/// within two quanta of it could not be told from it), through up to
/// [`MAX_CROSSINGS`] faces turned away.
fn hidden_depths(
    texture: &ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    texels: &[usize],
    parallel: bool,
) -> Vec<Option<u16>> {
    let camera = &texture.camera;
    let (w, bits) = (camera.width as usize, texture.depth_bits);
    let quantum = camera.depth_quantum(bits);
    let mesh = &target.object.mesh;
    let mut rays: Vec<(usize, Ray)> = (texels.iter().enumerate())
        .map(|(n, &k)| {
            let (u, v) = ((k % w) as f32 + 0.5, (k / w) as f32 + 0.5);
            let own = camera.depth_of_level(texture.depth[k], bits) - camera.depth_near;
            let ray = Ray {
                origin: camera.point(u, v, camera.depth_near),
                direction: camera.f,
                t_min: t_range.0.max(own + 2.0 * quantum),
                t_max: t_range.1,
            };
            (n, ray)
        })
        .collect();
    let mut depths = vec![None; texels.len()];
    for _ in 0..MAX_CROSSINGS {
        if rays.is_empty() {
            break;
        }
        let hits = cast(target, &rays, parallel);
        let mut onwards = Vec::new();
        for ((n, ray), hit) in rays.iter().zip(hits) {
            let Some(hit) = hit else { continue };
            if mesh.face_normal(hit.triangle as usize).dot(camera.f) < 0.0 {
                depths[*n] = Some(camera.level_of_depth(camera.depth_near + hit.t, bits));
            } else {
                // A face turned away: on past it, by a quantum.
                let ray = Ray {
                    t_min: hit.t + quantum,
                    ..*ray
                };
                onwards.push((*n, ray));
            }
        }
        rays = onwards;
    }
    depths
}

/// Whether rim texel `texel` (of a texture `width` wide) walks in from `side`: one in
/// two along the rim — on even rows for a side to the left or right, even columns up or
/// down.
pub(crate) fn every_other(texel: usize, width: usize, side: u8) -> bool {
    let along = match TEXEL_SIDES[side as usize] {
        (0, _) => texel % width,
        _ => texel / width,
    };
    along % 2 == 0
}

/// The closest hit of each ray, on the thread pool when `parallel` and there are many.
fn cast(target: &ObjectTracer, rays: &[(usize, Ray)], parallel: bool) -> Vec<Option<Hit>> {
    let rays: Vec<Ray> = rays.iter().map(|(_, ray)| *ray).collect();
    let mut hits: Vec<Option<Hit>> = vec![None; rays.len()];
    if parallel && rays.len() > RAYS_PER_TASK {
        (rays
            .par_chunks(RAYS_PER_TASK)
            .zip(hits.par_chunks_mut(RAYS_PER_TASK)))
        .for_each(|(rays, hits)| target.bvh.intersect_batch(rays, hits));
    } else {
        target.bvh.intersect_batch(&rays, &mut hits);
    }
    hits
}

#[cfg(test)]
mod tests {
    use glam::{DVec3, Vec3};
    use relief_core::mesh::Mesh;
    use relief_core::relief::DepthBits;
    use relief_core::scene::SceneObject;
    use relief_core::shading::Specular;

    use super::*;
    use crate::bake::bake;

    /// The texture from +z of `mesh`, 128² texels (a reach of 8).
    fn baked(mesh: Mesh, projection: SourceProjection) -> ReliefTexture {
        let object = SceneObject::new("boxes", mesh, DVec3::ZERO, Specular::default());
        let eye = Vec3::new(0.0, 0.0, 10.0);
        bake(
            &ObjectTracer::new(&object),
            eye,
            128,
            DepthBits::Sixteen,
            projection,
        )
        .expect("bakes")
    }

    /// A slab 2 × 2 wide hides, 2 behind it, one 1.8 wide: from every other rim
    /// texel's open side, the first texel in (of every fourth) whose ray meets the far
    /// slab — worked out from the texture's camera and the slab's extent — holds its
    /// front face's depth. The near slab's own back face, which every ray crosses
    /// first, is passed.
    #[test]
    fn a_rim_lists_the_surface_hidden_behind_it() {
        let mut mesh = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        mesh.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
            .expect("two boxes");
        let texture = baked(mesh, SourceProjection::Orthographic);
        let c = texture.camera;
        let (w, h) = (c.width as usize, c.height as usize);
        let reach = inward_reach(c.width, c.height);
        let mut expected = Vec::new();
        for (texel, open) in open_sides(&texture.depth, w, h, texture.depth_bits.empty()) {
            for side in (0..4u8).filter(|s| open & (1 << s) != 0 && every_other(texel, w, *s)) {
                let (di, dj) = TEXEL_SIDES[side as usize];
                let steps = (INWARD_STRIDE..=reach).step_by(INWARD_STRIDE as usize);
                let first = steps.into_iter().find_map(|inward| {
                    let i = (texel % w) as i32 - di * i32::from(inward);
                    let j = (texel / w) as i32 - dj * i32::from(inward);
                    let p = c.point(i as f32 + 0.5, j as f32 + 0.5, c.depth_near);
                    (p.x.abs() < 0.9 && p.y.abs() < 0.9).then_some((inward, p))
                });
                if let Some((inward, p)) = first {
                    // (The far slab's front face at z = −1.75; rays run along −z.)
                    let depth = c.level_of_depth(c.depth_near + p.z + 1.75, texture.depth_bits);
                    expected.push(Hidden {
                        texel: texel as u32,
                        side,
                        inward,
                        depth,
                    });
                }
            }
        }
        // (Of the rim's 4 × 126 texels, every other one, less the corners'.)
        assert!(
            expected.len() > 4 * 55,
            "most of the rim hides the far slab: {}",
            expected.len()
        );
        assert_eq!(texture.hidden.len(), expected.len());
        for (got, want) in texture.hidden.iter().zip(&expected) {
            assert_eq!(
                (got.texel, got.side, got.inward),
                (want.texel, want.side, want.inward)
            );
            assert!(got.depth.abs_diff(want.depth) <= 1, "{got:?} against {want:?}");
        }
        texture.check_hidden().expect("well formed");
    }

    /// A convex object hides nothing behind its rim, and a perspective texture (a
    /// sheet's: its winding says nothing of facing) does not look.
    #[test]
    fn nothing_is_listed_where_nothing_is_hidden_or_nothing_looked() {
        let one = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        assert!(baked(one, SourceProjection::Orthographic).hidden.is_empty());
        let mut two = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        two.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
            .expect("two boxes");
        assert!(baked(two, SourceProjection::Perspective).hidden.is_empty());
    }
}
