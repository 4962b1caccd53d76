//! Beam traversal: a block of an orthographic texture's parallel rays through the tree
//! at once.
//!
//! All of a bake's rays run along `f`, one through each texel centre. In the texture's
//! own coordinates — `u` and `v` along the texel axes `a` and `b`, in texels, and the
//! displacement `t` along `f` — a ray is a point `(i + ½, j + ½)` of the plane, and a
//! triangle is hit where its projection covers that point. So a block of rays is one
//! beam:
//!
//! - a child box is entered when its projection overlaps the block's texel centres
//!   and its near side lies before the farthest hit the block still needs, nearest
//!   child first (the order is the same for every ray of the beam);
//! - a leaf's triangle is projected once and its texel centres found as a rasteriser
//!   finds pixels, by edge functions over its bounding rectangle.
//!
//! # Exactness
//!
//! A box and a vertex are projected by the same arithmetic, in the same order, and
//! rounding is monotone, so a box's projection contains its triangles' projected
//! corners exactly: culling never loses a hit. Each edge's function is evaluated from
//! the same end (the lesser in `(u, v)`) by both triangles that share it, so a texel
//! centre on a shared edge is inside one or both, never neither: the bake is watertight.
//! The hit is the nearest over all triangles, as a single ray's traversal finds it
//! (`tests/tests/bvh_oracle.rs` checks both against an independent ray caster).

use glam::{Mat3, Vec3, Vec4};

use super::{Bvh, COUNT_SHIFT, Hit, LEAF, STACK, leaf_range};
use crate::prefetch::prefetch_lines;
use crate::tiles::{Block, TILE};

/// Relative slack on depth comparisons: an interpolated depth may fall a few units in
/// the last place below its corners' least, which bounds the box it is culled by.
const DEPTH_SLACK: f32 = 16.0 * f32::EPSILON;

/// The parallel rays of an orthographic texture: one along `f` through each texel
/// centre `origin + a·(i + ½) + b·(j + ½)`, searched for hits with displacement `t` in
/// `[t_min, t_max)`.
#[derive(Debug, Clone, Copy)]
pub struct ParallelRays {
    origin: Vec3,
    /// The rows of `[a b f]⁻¹`: `(u, v, t)` of a point `p` are their products with
    /// `p − origin`.
    to_u: Vec3,
    to_v: Vec3,
    to_t: Vec3,
    t_min: f32,
    t_max: f32,
}

impl ParallelRays {
    /// The rays, or `None` when `a`, `b` and `f` do not span space (or are not finite).
    pub fn new(origin: Vec3, a: Vec3, b: Vec3, f: Vec3, t_min: f32, t_max: f32) -> Option<Self> {
        let inverse = Mat3::from_cols(a, b, f).inverse();
        let rays = ParallelRays {
            origin,
            to_u: inverse.row(0),
            to_v: inverse.row(1),
            to_t: inverse.row(2),
            t_min,
            t_max,
        };
        (origin.is_finite() && inverse.is_finite() && t_min <= t_max).then_some(rays)
    }

    /// `(u, v, t)` of a point: the one formula the box projection mirrors lane by lane.
    #[inline(always)]
    fn project(&self, p: Vec3) -> Vec3 {
        let (dx, dy, dz) = (p.x - self.origin.x, p.y - self.origin.y, p.z - self.origin.z);
        let along = |row: Vec3| dx * row.x + dy * row.y + dz * row.z;
        Vec3::new(along(self.to_u), along(self.to_v), along(self.to_t))
    }
}

/// The least and greatest of `row · (p − origin)` over four boxes, by the arithmetic of
/// [`ParallelRays::project`].
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

/// The edge function of the directed edge `p → q` at `x`, evaluated from the lesser
/// end in `(u, v)` so that the two triangles sharing an edge get exactly opposite
/// values.
#[inline(always)]
fn edge(p: Vec3, q: Vec3, x: (f32, f32)) -> f32 {
    let from = |p: Vec3, q: Vec3| (q.x - p.x) * (x.1 - p.y) - (q.y - p.y) * (x.0 - p.x);
    if (p.x, p.y) <= (q.x, q.y) {
        from(p, q)
    } else {
        -from(q, p)
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

impl Bvh {
    /// The nearest hit of each ray of `block` (texel `(i, j)` for `(i, j)` in
    /// [`Block::pixels`] order, written to `hits` in that order).
    ///
    /// # Panics
    /// If the block is larger than [`TILE`]² or `hits` is not one slot per texel (caller
    /// bugs).
    pub fn intersect_parallel(&self, rays: &ParallelRays, block: Block, hits: &mut [Option<Hit>]) {
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

    fn trace_beam(&self, rays: &ParallelRays, block: Block, state: &mut BlockHits) {
        // The block's texel centres, in texels.
        let u_range = (block.x0 as f32 + 0.5, (block.x0 + block.width) as f32 - 0.5);
        let v_range = (block.y0 as f32 + 0.5, (block.y0 + block.height) as f32 - 0.5);
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
                let (u_lo, u_hi) = project_boxes(rays.to_u, rays.origin, min, max);
                let (v_lo, v_hi) = project_boxes(rays.to_v, rays.origin, min, max);
                let (t_lo, t_hi) = project_boxes(rays.to_t, rays.origin, min, max);
                let overlaps = u_hi.cmpge(Vec4::splat(u_range.0))
                    & u_lo.cmple(Vec4::splat(u_range.1))
                    & v_hi.cmpge(Vec4::splat(v_range.0))
                    & v_lo.cmple(Vec4::splat(v_range.1))
                    & t_lo.cmple(Vec4::splat(state.far + slack))
                    & t_hi.cmpge(Vec4::splat(rays.t_min - slack));
                let mut mask = overlaps.bitmask() & node.lanes;
                let t_lo = t_lo.to_array();
                let mut children = [(0u32, 0f32); 4];
                let mut n = 0;
                while mask != 0 {
                    let lane = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let count = node.count[lane];
                    let child = if count == 0 {
                        node.child[lane]
                    } else {
                        LEAF | count << COUNT_SHIFT | node.child[lane]
                    };
                    children[n] = (child, t_lo[lane]);
                    n += 1;
                    // A beam visits most children it enters, soon: start their fetches
                    // now, so the misses overlap instead of following one another.
                    if count == 0 {
                        prefetch_lines(std::slice::from_ref(&self.nodes[node.child[lane] as usize]));
                    } else {
                        let first = node.child[lane] as usize;
                        prefetch_lines(&self.triangles[first..first + count as usize]);
                    }
                }
                // Nearest child next; the others onto the stack, farthest first.
                let children = &mut children[..n];
                if n > 1 {
                    children.sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
                }
                let mut next = None;
                for &child in children.iter() {
                    if let Some(pending) = next.replace(child) {
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

    /// Rasterises the leaf `item`'s triangles over the block's texel centres, keeping
    /// each texel's nearest; true when any texel's nearest changed.
    fn raster_leaf(&self, rays: &ParallelRays, block: Block, item: u32, state: &mut BlockHits) -> bool {
        let mut changed = false;
        let first = (item & super::FIRST_MASK) as usize;
        let (i_end, j_end) = (block.x0 + block.width, block.y0 + block.height);
        for (k, tri) in self.triangles[leaf_range(item)].iter().enumerate() {
            let p = [rays.project(tri.v0), rays.project(tri.v1), rays.project(tri.v2)];
            let area = (p[1].x - p[0].x) * (p[2].y - p[0].y) - (p[1].y - p[0].y) * (p[2].x - p[0].x);
            // Edge-on (or degenerate, or out of range): no ray crosses it.
            if area == 0.0 || !area.is_finite() {
                continue;
            }
            let lo = p[0].min(p[1]).min(p[2]);
            let hi = p[0].max(p[1]).max(p[2]);
            if lo.z > state.far + (lo.z.abs() + state.far.abs()) * DEPTH_SLACK {
                continue;
            }
            // Texel centres `i + ½` within `[lo.x, hi.x]`, clipped to the block.
            let first_texel = |lo: f32, start: u32| ((lo - 0.5).ceil().max(start as f32)) as u32;
            let last_texel = |hi: f32, end: u32| ((hi - 0.5).floor() + 1.0).clamp(0.0, end as f32) as u32;
            let (i0, i1) = (first_texel(lo.x, block.x0), last_texel(hi.x, i_end));
            let (j0, j1) = (first_texel(lo.y, block.y0), last_texel(hi.y, j_end));
            for j in j0..j1 {
                let y = j as f32 + 0.5;
                for i in i0..i1 {
                    let x = (i as f32 + 0.5, y);
                    let (e0, e1, e2) = (edge(p[1], p[2], x), edge(p[2], p[0], x), edge(p[0], p[1], x));
                    let inside = if area > 0.0 {
                        e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0
                    } else {
                        e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0
                    };
                    if !inside {
                        continue;
                    }
                    let sum = e0 + e1 + e2;
                    if sum == 0.0 {
                        continue;
                    }
                    let (w1, w2) = (e1 / sum, e2 / sum);
                    let t = (1.0 - w1 - w2) * p[0].z + w1 * p[1].z + w2 * p[2].z;
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
