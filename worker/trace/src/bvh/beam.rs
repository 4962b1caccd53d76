//! Beam traversal: a block of an image plane's rays through the tree at once.
//!
//! A bake casts one ray through each texel centre of the texture's image plane (and a
//! reference frame one through each sample of its pixels, from the eye): all
//! along `f` (orthographic), or all from a centre of projection `C` (perspective). In
//! the plane's own coordinates — `u` and `v` along the texel axes `a` and `b`, in
//! texels — a ray is a point `(i + ½, j + ½)`, and a triangle is hit where its
//! projection on the plane (along `f`, or from `C`) covers that point. So a block of
//! rays is one beam:
//!
//! - a child box is entered when it is not wholly outside any of the four planes that
//!   bound the block's rays (through `C` for a perspective beam), and its near side
//!   lies before the farthest hit the block still needs; nearest child first (the
//!   order is the same for every ray of the beam);
//! - a leaf's triangle is projected once and its texel centres found as a rasteriser
//!   finds pixels, by edge functions over its bounding rectangle; depth and barycentrics
//!   interpolated linearly on the plane, or perspective-correctly (`1/d` linear).
//!
//! # Exactness
//!
//! Orthographic: a box and a vertex are projected by the same arithmetic, in the same
//! order, and rounding is monotone, so a box's bounds contain its triangles' projected
//! corners exactly: culling never loses a hit. Perspective: the projection divides, so
//! the side planes keep a slack ([`PERSPECTIVE_SLACK`]). Each edge's function is
//! evaluated from the same end (the lesser in `(u, v)`) by both triangles that share
//! it, so a texel centre on a shared edge is inside one or both, never neither: the
//! bake is watertight. The hit is the nearest over all triangles, as a single ray's
//! traversal finds it (`tests/tests/bvh_oracle.rs` checks both against an independent
//! ray caster).

use glam::{Mat3, Vec3, Vec4};

use super::{Bvh, FIRST_MASK, Hit, LEAF, STACK, children_farthest_first, leaf_range};
use crate::prefetch::prefetch_lines;
use crate::tiles::{Block, TILE};

/// Relative slack on depth comparisons: an interpolated depth may fall a few units in
/// the last place below its corners' least, which bounds the box it is culled by.
const DEPTH_SLACK: f32 = 16.0 * f32::EPSILON;

/// Relative slack on a perspective beam's side planes, against the rounding of the
/// division that projects a vertex: a hundredth of a texel or so at the plane.
const PERSPECTIVE_SLACK: f32 = 1e-5;

/// How far from square to `f` (cosine) the texel axes of a perspective beam may be:
/// its planes through the centre take `f` for the plane's normal.
const SQUARE_TOLERANCE: f32 = 1e-4;

/// The rays of an image plane (a texture's, or a reference frame's samples), one through each texel centre
/// `origin + a·(i + ½) + b·(j + ½)`: along `f`, or from a centre of projection. A ray's
/// parameter `t` is its displacement along `f` past the plane (its direction has
/// component 1 along `f`), searched in `[t_min, t_max)`.
#[derive(Debug, Clone, Copy)]
pub struct PlaneRays {
    origin: Vec3,
    /// The rows of `[a b f]⁻¹`: the orthographic `(u, v, t)` of a point `p` are their
    /// products with `p − origin`.
    to_u: Vec3,
    to_v: Vec3,
    to_t: Vec3,
    centre: Option<Centre>,
    t_min: f32,
    t_max: f32,
}

/// A perspective texture's centre of projection `C`, with what projecting from it
/// needs.
#[derive(Debug, Clone, Copy)]
struct Centre {
    at: Vec3,
    /// `f`, unit: a point's depth from `C` is `(p − C)·f`.
    f: Vec3,
    /// The plane's distance from `C`, `h = (origin − C)·f`.
    h: f32,
    /// `(origin − C)·to_u` and `·to_v`: where the foot of `C` lies, in texels.
    cu: f32,
    cv: f32,
}

impl PlaneRays {
    /// Parallel rays along `f`, or `None` when `a`, `b` and `f` do not span space (or
    /// are not finite).
    pub fn parallel(origin: Vec3, a: Vec3, b: Vec3, f: Vec3, t_min: f32, t_max: f32) -> Option<Self> {
        let inverse = Mat3::from_cols(a, b, f).inverse();
        let rays = PlaneRays {
            origin,
            to_u: inverse.row(0),
            to_v: inverse.row(1),
            to_t: inverse.row(2),
            centre: None,
            t_min,
            t_max,
        };
        (origin.is_finite() && inverse.is_finite() && t_min <= t_max).then_some(rays)
    }

    /// Rays from `centre` through the texel centres, for `f` square to `a` and `b` and
    /// the centre in front of the plane; `None` otherwise. Every triangle traced must
    /// lie beyond the plane through the centre square to `f` (a perspective texture's
    /// object does: its bounds lie beyond its image plane).
    pub fn from_centre(
        centre: Vec3,
        origin: Vec3,
        a: Vec3,
        b: Vec3,
        f: Vec3,
        t_min: f32,
        t_max: f32,
    ) -> Option<Self> {
        let mut rays = Self::parallel(origin, a, b, f, t_min, t_max)?;
        let f = f.normalize_or_zero();
        let h = (origin - centre).dot(f);
        let square = a.dot(f).abs() <= SQUARE_TOLERANCE * a.length()
            && b.dot(f).abs() <= SQUARE_TOLERANCE * b.length();
        if !(centre.is_finite() && h.is_normal() && h > 0.0 && square) {
            return None;
        }
        rays.centre = Some(Centre {
            at: centre,
            f,
            h,
            cu: (origin - centre).dot(rays.to_u),
            cv: (origin - centre).dot(rays.to_v),
        });
        Some(rays)
    }

    /// `(u, v, t)` of a point, orthographic: the one formula the box bounds mirror lane
    /// by lane.
    #[inline(always)]
    fn project(&self, p: Vec3) -> Vec3 {
        let (dx, dy, dz) = (p.x - self.origin.x, p.y - self.origin.y, p.z - self.origin.z);
        let along = |row: Vec3| dx * row.x + dy * row.y + dz * row.z;
        Vec3::new(along(self.to_u), along(self.to_v), along(self.to_t))
    }
}

impl Centre {
    /// `(u, v)` on the plane of the ray from `C` through `p`, and `p`'s depth `d` from
    /// `C` along `f` (its `t` is `d − h`).
    #[inline(always)]
    fn project(&self, rays: &PlaneRays, p: Vec3) -> (f32, f32, f32) {
        let r = p - self.at;
        let d = r.dot(self.f);
        let scale = self.h / d;
        (
            r.dot(rays.to_u) * scale - self.cu,
            r.dot(rays.to_v) * scale - self.cv,
            d,
        )
    }
}

/// The least and greatest of `row · (p − origin)` over four boxes, by the arithmetic of
/// [`PlaneRays::project`].
#[inline(always)]
fn project_boxes(row: Vec3, origin: Vec3, min: [Vec4; 3], max: [Vec4; 3]) -> (Vec4, Vec4) {
    let mut lo = Vec4::ZERO;
    let mut hi = Vec4::ZERO;
    for axis in 0..3 {
        let (near, far) = if row[axis] >= 0.0 {
            (min[axis], max[axis])
        } else {
            (max[axis], min[axis])
        };
        let o = Vec4::splat(origin[axis]);
        let r = Vec4::splat(row[axis]);
        let (l, h) = ((near - o) * r, (far - o) * r);
        // (The first term alone, then sums left to right, as `project` adds.)
        if axis == 0 {
            (lo, hi) = (l, h);
        } else {
            (lo, hi) = (lo + l, hi + h);
        }
    }
    (lo, hi)
}

/// The half-spaces that bound a block's rays: a box is entered only when, for each
/// side, some of it lies within `n · (p − at) ≥ k − slack`; and the depth row, whose
/// least over a box less `t_offset` is the box's near side in `t`.
struct BeamBounds {
    at: Vec3,
    sides: [(Vec3, f32); 4],
    slack: f32,
    depth_row: Vec3,
    t_offset: f32,
}

impl BeamBounds {
    fn of(rays: &PlaneRays, block: Block) -> Self {
        // The block's texel centres, in texels.
        let (u_lo, u_hi) = (block.x0 as f32 + 0.5, (block.x0 + block.width) as f32 - 0.5);
        let (v_lo, v_hi) = (block.y0 as f32 + 0.5, (block.y0 + block.height) as f32 - 0.5);
        match rays.centre {
            None => BeamBounds {
                at: rays.origin,
                // u ≥ u_lo, −u ≥ −u_hi, and the same in v: mirrored rows round exactly
                // as the originals, so the bounds stay exact.
                sides: [
                    (rays.to_u, u_lo),
                    (-rays.to_u, -u_hi),
                    (rays.to_v, v_lo),
                    (-rays.to_v, -v_hi),
                ],
                slack: 0.0,
                depth_row: rays.to_t,
                t_offset: 0.0,
            },
            Some(c) => {
                // u(p) ≥ u_lo ⇔ (p − C)·(h·to_u − (cu + u_lo)·f) ≥ 0 for p beyond C.
                let side =
                    |row: Vec3, foot: f32, bound: f32, sign: f32| (row * c.h - c.f * (foot + bound)) * sign;
                let sides = [
                    (side(rays.to_u, c.cu, u_lo, 1.0), 0.0),
                    (side(rays.to_u, c.cu, u_hi, -1.0), 0.0),
                    (side(rays.to_v, c.cv, v_lo, 1.0), 0.0),
                    (side(rays.to_v, c.cv, v_hi, -1.0), 0.0),
                ];
                let reach = c.h + rays.t_max.abs();
                let widest = sides.iter().map(|(n, _)| n.length()).fold(0.0, f32::max);
                BeamBounds {
                    at: c.at,
                    sides,
                    slack: PERSPECTIVE_SLACK * widest * reach,
                    depth_row: c.f,
                    t_offset: c.h,
                }
            }
        }
    }
}

/// The nearest hit found so far for each texel of a block.
struct BlockHits {
    t: [f32; TILE * TILE],
    /// Leaf-order triangle and barycentrics of corners 1 and 2, for texels hit.
    found: [Option<(u32, f32, f32)>; TILE * TILE],
    /// The farthest `t` any texel still accepts: boxes beyond it are skipped.
    far: f32,
    /// Texels with no hit yet: while any is left, `far` stays the rays' `t_max`.
    unhit: usize,
}

/// A triangle's corners on the plane: `(u, v)`, `t`, and for a perspective beam `1/d`
/// (what interpolates linearly on the plane).
struct Projected {
    uv: [(f32, f32); 3],
    t: [f32; 3],
    inv_d: Option<[f32; 3]>,
}

impl Bvh {
    /// The nearest hit of each ray of `block` (texel `(i, j)` for `(i, j)` in
    /// [`Block::pixels`] order, written to `hits` in that order).
    ///
    /// # Panics
    /// If the block is larger than [`TILE`]² or `hits` is not one slot per texel (caller
    /// bugs).
    pub fn intersect_block(&self, rays: &PlaneRays, block: Block, hits: &mut [Option<Hit>]) {
        let (width, height) = (block.width as usize, block.height as usize);
        assert!(width <= TILE && height <= TILE, "a beam block is at most TILE²");
        assert_eq!(hits.len(), width * height, "one hit slot per texel");
        let mut state = BlockHits {
            t: [rays.t_max; TILE * TILE],
            found: [None; TILE * TILE],
            far: rays.t_max,
            unhit: width * height,
        };
        if !self.triangles.is_empty() && width > 0 && height > 0 {
            self.trace_beam(rays, block, &mut state);
        }
        for (k, slot) in hits.iter_mut().enumerate() {
            *slot = state.found[k].map(|(triangle, u, v)| Hit {
                t: state.t[k],
                u,
                v,
                triangle: self.triangles[triangle as usize].id,
            });
        }
    }

    fn trace_beam(&self, rays: &PlaneRays, block: Block, state: &mut BlockHits) {
        let bounds = BeamBounds::of(rays, block);
        let slack = (rays.t_min.abs() + rays.t_max.abs()) * DEPTH_SLACK;
        let mut stack = [(0u32, 0f32); STACK];
        let mut depth = 0;
        let mut item = Some(0u32);
        while let Some(current) = item {
            item = None;
            if current & LEAF != 0 {
                if self.raster_leaf(rays, block, current, state) && state.unhit == 0 {
                    state.far = state.t[..(block.width * block.height) as usize]
                        .iter()
                        .fold(f32::NEG_INFINITY, |a, &b| a.max(b));
                }
            } else {
                let node = &self.nodes[current as usize];
                let min = [node.min_x, node.min_y, node.min_z];
                let max = [node.max_x, node.max_y, node.max_z];
                let mut inside = node.lanes;
                for (normal, k) in bounds.sides {
                    let (_, hi) = project_boxes(normal, bounds.at, min, max);
                    inside &= hi.cmpge(Vec4::splat(k - bounds.slack)).bitmask();
                }
                let (t_lo, t_hi) = project_boxes(bounds.depth_row, bounds.at, min, max);
                let offset = Vec4::splat(bounds.t_offset);
                let (t_lo, t_hi) = (t_lo - offset, t_hi - offset);
                inside &= (t_lo.cmple(Vec4::splat(state.far + slack))
                    & t_hi.cmpge(Vec4::splat(rays.t_min - slack)))
                .bitmask();
                let (children, n) = children_farthest_first(node, inside, t_lo.to_array());
                let mut next = None;
                for &(child, t_near) in &children[..n] {
                    // A beam visits most children it enters, soon: start their fetches
                    // now, so the misses overlap instead of following one another.
                    if child & LEAF != 0 {
                        prefetch_lines(&self.triangles[leaf_range(child)]);
                    } else {
                        prefetch_lines(std::slice::from_ref(&self.nodes[child as usize]));
                    }
                    // Nearest child next; the others onto the stack, farthest first.
                    if let Some(pending) = next.replace((child, t_near)) {
                        stack[depth] = pending;
                        depth += 1;
                    }
                }
                item = next.map(|(child, _)| child);
            }
            if item.is_none() {
                // Pop the next item that can still hold a nearer hit.
                while depth > 0 {
                    depth -= 1;
                    let (pending, t_near) = stack[depth];
                    if t_near <= state.far + slack {
                        item = Some(pending);
                        break;
                    }
                }
            }
        }
    }

    /// A triangle's corners on the plane, or `None` for a perspective beam when one
    /// lies at or behind the centre (no such triangle is traced; see
    /// [`PlaneRays::from_centre`]).
    #[inline(always)]
    fn project_triangle(rays: &PlaneRays, corners: [Vec3; 3]) -> Option<Projected> {
        match &rays.centre {
            None => {
                let p = corners.map(|c| rays.project(c));
                Some(Projected {
                    uv: p.map(|p| (p.x, p.y)),
                    t: p.map(|p| p.z),
                    inv_d: None,
                })
            }
            Some(c) => {
                let p = corners.map(|corner| c.project(rays, corner));
                if !p.iter().all(|&(_, _, d)| d > 0.0) {
                    return None;
                }
                Some(Projected {
                    uv: p.map(|(u, v, _)| (u, v)),
                    t: p.map(|(_, _, d)| d - c.h),
                    inv_d: Some(p.map(|(_, _, d)| 1.0 / d)),
                })
            }
        }
    }

    /// Rasterises the leaf `item`'s triangles over the block's texel centres, keeping
    /// each texel's nearest; true when any texel's nearest changed.
    fn raster_leaf(&self, rays: &PlaneRays, block: Block, item: u32, state: &mut BlockHits) -> bool {
        let mut changed = false;
        let first = (item & FIRST_MASK) as usize;
        let (i_end, j_end) = (block.x0 + block.width, block.y0 + block.height);
        for (k, tri) in self.triangles[leaf_range(item)].iter().enumerate() {
            let Some(p) = Self::project_triangle(rays, [tri.v0, tri.v1, tri.v2]) else {
                continue;
            };
            let [p0, p1, p2] = p.uv;
            let area = (p1.0 - p0.0) * (p2.1 - p0.1) - (p1.1 - p0.1) * (p2.0 - p0.0);
            // Edge-on (or degenerate, or out of range): no ray crosses it.
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            let t_near = p.t[0].min(p.t[1]).min(p.t[2]);
            if t_near > state.far + (t_near.abs() + state.far.abs()) * DEPTH_SLACK {
                continue;
            }
            let (u_lo, u_hi) = (p0.0.min(p1.0).min(p2.0), p0.0.max(p1.0).max(p2.0));
            let (v_lo, v_hi) = (p0.1.min(p1.1).min(p2.1), p0.1.max(p1.1).max(p2.1));
            // Texel centres `i + ½` within `[lo, hi]`, clipped to the block.
            let first_texel = |lo: f32, start: u32| ((lo - 0.5).ceil().max(start as f32)) as u32;
            let last_texel = |hi: f32, end: u32| ((hi - 0.5).floor() + 1.0).clamp(0.0, end as f32) as u32;
            let (i0, i1) = (first_texel(u_lo, block.x0), last_texel(u_hi, i_end));
            let (j0, j1) = (first_texel(v_lo, block.y0), last_texel(v_hi, j_end));
            for j in j0..j1 {
                let y = j as f32 + 0.5;
                for i in i0..i1 {
                    let x = (i as f32 + 0.5, y);
                    let (e0, e1, e2) = (edge(p1, p2, x), edge(p2, p0, x), edge(p0, p1, x));
                    let inside = if area > 0.0 {
                        e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0
                    } else {
                        e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0
                    };
                    let sum = e0 + e1 + e2;
                    if !inside || sum == 0.0 {
                        continue;
                    }
                    // Weights on the plane; on the triangle, perspective-correct.
                    let (w1, w2) = (e1 / sum, e2 / sum);
                    let (t, w1, w2) = match p.inv_d {
                        None => ((1.0 - w1 - w2) * p.t[0] + w1 * p.t[1] + w2 * p.t[2], w1, w2),
                        Some(inv_d) => {
                            let (q0, q1, q2) = ((1.0 - w1 - w2) * inv_d[0], w1 * inv_d[1], w2 * inv_d[2]);
                            let inv = q0 + q1 + q2;
                            // t = 1/Σ(wᵢ/dᵢ) − h, written Σ(wᵢtᵢ/dᵢ)/Σ(wᵢ/dᵢ) (as Σwᵢ = 1 and
                            // tᵢ = dᵢ − h): no cancellation when `h` dwarfs the depths.
                            let t = (q0 * p.t[0] + q1 * p.t[1] + q2 * p.t[2]) / inv;
                            (t, q1 / inv, q2 / inv)
                        }
                    };
                    let texel = ((j - block.y0) * block.width + (i - block.x0)) as usize;
                    if t >= rays.t_min && t < state.t[texel] {
                        state.unhit -= usize::from(state.found[texel].is_none());
                        state.t[texel] = t;
                        state.found[texel] = Some(((first + k) as u32, w1, w2));
                        changed = true;
                    }
                }
            }
        }
        changed
    }
}

/// The edge function of the directed edge `p → q` at `x`, evaluated from the lesser
/// end in `(u, v)` so that the two triangles sharing an edge get exactly opposite
/// values.
#[inline(always)]
fn edge(p: (f32, f32), q: (f32, f32), x: (f32, f32)) -> f32 {
    let from = |p: (f32, f32), q: (f32, f32)| (q.0 - p.0) * (x.1 - p.1) - (q.1 - p.1) * (x.0 - p.0);
    if p <= q { from(p, q) } else { -from(q, p) }
}
