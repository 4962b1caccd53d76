//! What a texture's rim hides: the surfaces a turn of the eye uncovers beside its
//! outline ([`Hidden`]).
//!
//! Seen from the side, an animal's far legs stand hidden behind its near ones; a few
//! degrees round they step out beside them. The texture holds no texel of them and its
//! planes no hint that anything is there: the gaps the client predicts from
//! neighbouring depths (`relief_render::validity::critical`) lie between two surfaces
//! the texture shows, and beside a rim there is only sky. So the bake looks past the
//! rim. From rim texels on even rows (for a side open to the left or right) or even
//! columns (up or down) — one in two along most rims — it looks inwards, away from each
//! open side, at every [`INWARD_STRIDE`]th texel up to [`inward_reach`] over the
//! object's covered texels: it casts that texel's ray on past its own surface, through
//! the faces turned away from the rays it meets (its own surface's far side), to the
//! first face turned towards them.
//!
//! Not every step is cast. The deepest goes first, then, where it finds nothing, the
//! middle one; a step that finds a surface is followed by the next towards the rim,
//! until one finds none, and from the nearest that found it on a texel at a time, until
//! one finds none (at worst the stride that found nothing, cast again). The walk
//! records the nearest step of that run: where the hidden surface lies and how deep,
//! what the client needs to predict how far a turn brings it out (a surface found a
//! stride late is predicted to come out as much later: past the bunny's near ear, its
//! far ear 5.2 texels out where by texels it is 7.3). A rim that hides nothing (most of
//! an outline) costs one step or two (each up to [`MAX_CROSSINGS`] + 1 casts), and the
//! bake 7–17 % more, the steps texel by texel up to 5 % on that (every step of every
//! rim texel, from the rim out, cost 2–3 times the bake). So a surface that reaches
//! neither the deepest step nor the middle one (a thin one just behind the rim) is
//! missed.
//!
//! What the walk steps over is taken as the rim's own surface: a nearer surface seen
//! beside it would be a step in depth the client measures apart.
//!
//! Only closed solids' orthographic textures look: a sheet's faces (leaves, two-sided:
//! [`EdgeCensus::is_sheets`](relief_core::mesh::EdgeCensus::is_sheets)) say nothing by
//! their winding of which way they look, and a perspective texture is asked only for
//! sheets.

use relief_core::relief::{Hidden, ReliefTexture, SourceProjection, TEXEL_SIDES};

use crate::bvh::Ray;
use crate::rim::{cast_rays, open_sides};
use crate::tracer::ObjectTracer;

/// How many faces turned away from the rays a ray may pass looking for one that faces
/// them: its own surface's far side, then (on a mesh of shells, or grazing a fold) one
/// more. What lies past that many is left unknown, as if there were nothing.
pub const MAX_CROSSINGS: usize = 2;

/// Texels between the steps looked at inwards from a rim texel, and from the rim to
/// the first, before the walk goes on a texel at a time: a rim that hides nothing
/// costs one step or two whatever the reach, one that hides something a step a stride
/// and up to 4 more to find its nearest texel (the last the stride that found nothing,
/// cast again). None is cast at the rim texel itself: a
/// surface behind it that reached past it would cover its open neighbour, which would
/// then not be open.
pub const INWARD_STRIDE: u8 = 4;

/// How far in from the rim a texture looks for what it hides: a sixteenth of its
/// larger edge (16 texels of a 256² texture, 32 of a 512²; under [`INWARD_STRIDE`], so
/// nothing, below 64²). A surface further in comes out only past a turn that moves it
/// that far: 8–16 pixels at half a pixel to a texel, by when the gaps' tolerance has
/// retired the texture.
pub fn inward_reach(width: u32, height: u32) -> u8 {
    (width.max(height) / 16).clamp(1, u32::from(u8::MAX)) as u8
}

/// One open side of a rim texel being walked (see the module docs).
#[derive(Clone, Copy)]
struct Walk {
    /// The rim texel.
    texel: usize,
    side: u8,
    /// The step looked at now, texels in from the rim.
    inward: u8,
    /// The middle step, looked at if the deepest finds nothing (0: none).
    middle: u8,
    /// Texels from one step to the next: [`INWARD_STRIDE`], then 1 once the strides
    /// have found the nearest of theirs.
    stride: u8,
    /// The nearest step so far that found a hidden surface, and its depth level.
    found: Option<(u8, u16)>,
}

impl Walk {
    /// The walk at `inward` texels in.
    fn at(&self, inward: u8) -> Hidden {
        Hidden {
            texel: self.texel as u32,
            side: self.side,
            inward,
            depth: 0,
        }
    }

    /// Where the walk goes once its step found `hit` (a depth level behind the rim
    /// texel's own), or `Err` with what it found once it ends.
    fn next(mut self, hit: Option<u16>) -> Result<Walk, Option<Hidden>> {
        match (hit, self.found) {
            (Some(depth), _) => {
                self.found = Some((self.inward, depth));
                match self.inward.checked_sub(self.stride).filter(|&k| k > 0) {
                    Some(inward) => Ok(Walk { inward, ..self }),
                    None => self.texel_by_texel(),
                }
            }
            (None, None) if self.middle > 0 && self.middle < self.inward => Ok(Walk {
                inward: self.middle,
                middle: 0,
                ..self
            }),
            (None, Some(_)) => self.texel_by_texel(),
            (None, None) => Err(self.hidden()),
        }
    }

    /// Once the strides end, on from the nearest they found towards the rim a texel
    /// at a time (those between it and the stride that found nothing, or the rim),
    /// until a step finds nothing.
    fn texel_by_texel(self) -> Result<Walk, Option<Hidden>> {
        match self.found {
            Some((nearest, _)) if self.stride > 1 && nearest > 1 => Ok(Walk {
                inward: nearest - 1,
                stride: 1,
                ..self
            }),
            _ => Err(self.hidden()),
        }
    }

    /// What the walk found, as the texture lists it.
    fn hidden(&self) -> Option<Hidden> {
        let (inward, depth) = self.found?;
        Some(Hidden {
            depth,
            ..self.at(inward)
        })
    }
}

/// Fills `texture.hidden` (see the module docs) for a texture of `target` made in
/// `projection`: `t_range` is the bake's own rays' search from the texture's near
/// depth; on the thread pool when `parallel`. (It runs once begun, as the rim's rays
/// do: at most a few rays a rim texel.)
pub(crate) fn find_hidden(
    texture: &mut ReliefTexture,
    target: &ObjectTracer,
    t_range: (f32, f32),
    projection: SourceProjection,
    parallel: bool,
) {
    if projection != SourceProjection::Orthographic || target.object.edge_census().is_sheets() {
        return;
    }
    let camera = texture.camera;
    let (w, h) = (camera.width, camera.height);
    let empty = texture.depth_bits.empty();
    let reach = inward_reach(w, h);
    // The texel `hidden` lies behind, if it is inside the texture and covered.
    let behind = |hidden: Hidden| -> Option<usize> {
        let (i, j) = hidden.behind(w, h)?;
        let k = (j * w + i) as usize;
        (texture.depth[k] != empty).then_some(k)
    };
    let mut walks: Vec<Walk> = open_sides(&texture.depth, w as usize, h as usize, empty)
        .into_iter()
        .flat_map(|(texel, open)| {
            (0..TEXEL_SIDES.len() as u8)
                .filter(move |s| open & (1 << s) != 0 && every_other(texel, w as usize, *s))
                .map(move |side| Walk {
                    texel,
                    side,
                    inward: 0,
                    middle: 0,
                    stride: INWARD_STRIDE,
                    found: None,
                })
        })
        .filter_map(|walk| {
            // The deepest step over covered texels (a gap to the sky ends the object's
            // surface there).
            let covered = (1..=reach).take_while(|&k| behind(walk.at(k)).is_some()).last()?;
            let steps = covered / INWARD_STRIDE;
            (steps > 0).then_some(Walk {
                inward: steps * INWARD_STRIDE,
                middle: steps.div_ceil(2) * INWARD_STRIDE,
                ..walk
            })
        })
        .collect();
    let mut found: Vec<Hidden> = Vec::new();
    while !walks.is_empty() {
        // (Every step a walk takes lies over covered texels: its deepest did, and
        // every one nearer the rim.)
        let (stepped, texels): (Vec<Walk>, Vec<usize>) = (walks.iter())
            .filter_map(|walk| Some((*walk, behind(walk.at(walk.inward))?)))
            .unzip();
        let hits = hidden_depths(texture, target, t_range, &texels, parallel);
        walks = Vec::new();
        for (walk, hit) in stepped.into_iter().zip(hits) {
            let hit = hit.filter(|&depth| depth > texture.depth[walk.texel]);
            match walk.next(hit) {
                Ok(onwards) => walks.push(onwards),
                Err(hidden) => found.extend(hidden),
            }
        }
    }
    found.sort_unstable_by_key(Hidden::key);
    texture.hidden = found;
}

/// For each of `texels` of `texture`, the depth level of the first face behind its
/// own surface that faces the rays: its ray cast on from just past its depth (a surface
/// within two quanta of it could not be told from it), past up to [`MAX_CROSSINGS`]
/// faces turned away.
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
    // (Each ray beside the texel it is for, as the rays still searching shrink.)
    let mut searching: Vec<(usize, Ray)> = (texels.iter().enumerate())
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
    for _ in 0..=MAX_CROSSINGS {
        if searching.is_empty() {
            break;
        }
        let rays: Vec<Ray> = searching.iter().map(|(_, ray)| *ray).collect();
        let hits = cast_rays(target, &rays, parallel);
        let mut onwards = Vec::new();
        for ((n, ray), hit) in searching.iter().zip(hits) {
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
        searching = onwards;
    }
    depths
}

/// Whether rim texel `texel` (of a texture `width` wide) looks in from `side`: on even
/// rows for a side open to the left or right, on even columns up or down.
pub(crate) fn every_other(texel: usize, width: usize, side: u8) -> bool {
    let along = match TEXEL_SIDES[side as usize] {
        (0, _) => texel % width,
        _ => texel / width,
    };
    along % 2 == 0
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

    /// What the walks of `texture` should find where `hidden_at(p)` says whether the
    /// ray through plane point `p` meets a face behind the near slab: the rule of the
    /// module docs (the deepest step over covered texels, else the middle one, then
    /// towards the rim while they find it, by strides and then by texels), written out
    /// again step by step.
    fn expected(texture: &ReliefTexture, hidden_at: impl Fn(Vec3) -> bool) -> Vec<Hidden> {
        let c = texture.camera;
        let (w, h) = (c.width as usize, c.height as usize);
        let reach = inward_reach(c.width, c.height);
        let empty = texture.depth_bits.empty();
        let mut expected = Vec::new();
        for (texel, open) in open_sides(&texture.depth, w, h, empty) {
            for side in (0..4u8).filter(|s| open & (1 << s) != 0 && every_other(texel, w, *s)) {
                let (di, dj) = TEXEL_SIDES[side as usize];
                let point = |inward: u8| {
                    let i = (texel % w) as i32 - di * i32::from(inward);
                    let j = (texel / w) as i32 - dj * i32::from(inward);
                    let inside = (0..w as i32).contains(&i) && (0..h as i32).contains(&j);
                    let covered = inside && texture.depth[j as usize * w + i as usize] != empty;
                    covered.then(|| c.point(i as f32 + 0.5, j as f32 + 0.5, c.depth_near))
                };
                let covered = (1..=reach).take_while(|&k| point(k).is_some()).count() as u8;
                let steps = covered / INWARD_STRIDE;
                let hit = |k: u8| point(k).is_some_and(&hidden_at);
                let (top, middle) = (steps * INWARD_STRIDE, steps.div_ceil(2) * INWARD_STRIDE);
                let Some(mut k) = [top, middle].into_iter().find(|&k| k > 0 && hit(k)) else {
                    continue;
                };
                while k > INWARD_STRIDE && hit(k - INWARD_STRIDE) {
                    k -= INWARD_STRIDE;
                }
                while k > 1 && hit(k - 1) {
                    k -= 1;
                }
                let p = point(k).expect("covered");
                // (The far faces at z = −1.75; rays run along −z.)
                let depth = c.level_of_depth(c.depth_near + p.z + 1.75, texture.depth_bits);
                expected.push(Hidden {
                    texel: texel as u32,
                    side,
                    inward: k,
                    depth,
                });
            }
        }
        expected
    }

    fn assert_found(texture: &ReliefTexture, expected: &[Hidden]) {
        assert_eq!(texture.hidden.len(), expected.len());
        for (got, want) in texture.hidden.iter().zip(expected) {
            assert_eq!(
                (got.texel, got.side, got.inward),
                (want.texel, want.side, want.inward)
            );
            assert!(got.depth.abs_diff(want.depth) <= 1, "{got:?} against {want:?}");
        }
        texture.check_hidden().expect("well formed");
    }

    /// A slab 2 × 2 wide hides, 2 behind it, one 1.8 wide: from every other rim
    /// texel's open side, the nearest step in whose ray meets the far slab — worked out
    /// from the texture's camera and the slab's extent — holds its front face's depth.
    /// The near slab's own back face, which every ray crosses first, is passed.
    #[test]
    fn a_rim_lists_the_surface_hidden_behind_it() {
        let mut mesh = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        mesh.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
            .expect("two boxes");
        let texture = baked(mesh, SourceProjection::Orthographic);
        let expected = expected(&texture, |p| p.x.abs() < 0.9 && p.y.abs() < 0.9);
        // (Of the rim's 4 × 126 texels, every other one, less the corners'.)
        assert!(
            expected.len() > 4 * 55,
            "most of the rim hides the far slab: {}",
            expected.len()
        );
        assert_found(&texture, &expected);
    }

    /// A strip hidden just behind one rim, short of the deepest step (a texture of 128²
    /// looks 8 texels in, the strip lies 2–4 texels in): found by the middle step, and
    /// its nearest texel then a texel at a time.
    #[test]
    fn a_surface_just_behind_the_rim_is_found_by_the_middle_step() {
        let mut mesh = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        mesh.append(Mesh::cuboid(
            Vec3::new(0.06, 1.0, 0.5),
            Vec3::new(-0.93, 0.0, -2.0),
        ))
        .expect("a slab and a strip");
        let texture = baked(mesh, SourceProjection::Orthographic);
        let expected = expected(&texture, |p| (-0.96..-0.9).contains(&p.x) && p.y.abs() < 0.5);
        assert!(
            expected
                .iter()
                .all(|h| h.side == 0 && (2..INWARD_STRIDE).contains(&h.inward)),
            "{expected:?}"
        );
        // (Rows of the strip's 64, every other one.)
        assert!(expected.len() >= 30, "the strip is found: {}", expected.len());
        assert_found(&texture, &expected);
    }

    /// A convex object hides nothing behind its rim; a perspective texture, and one
    /// of sheets (the near slab left open at the back: its winding says nothing of
    /// facing), do not look.
    #[test]
    fn nothing_is_listed_where_nothing_is_hidden_or_nothing_looked() {
        let two = || {
            let mut two = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
            two.append(Mesh::cuboid(Vec3::new(1.8, 1.8, 0.5), Vec3::new(0.0, 0.0, -2.0)))
                .expect("two boxes");
            two
        };
        assert!(!baked(two(), SourceProjection::Orthographic).hidden.is_empty());
        let one = Mesh::cuboid(Vec3::new(2.0, 2.0, 0.5), Vec3::ZERO);
        assert!(baked(one, SourceProjection::Orthographic).hidden.is_empty());
        assert!(baked(two(), SourceProjection::Perspective).hidden.is_empty());
        let mut open = two();
        // (The near slab's quad facing −z, its triangles 8 and 9.)
        open.triangles.drain(8..10);
        assert!(open.edge_census().is_sheets());
        assert!(baked(open, SourceProjection::Orthographic).hidden.is_empty());
    }
}
