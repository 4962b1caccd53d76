//! A bounding-volume hierarchy over the triangles of one mesh.
//!
//! Built as a binary tree with binned SAH (`build.rs`), then collapsed into a 4-wide tree
//! whose nodes keep their children's boxes in structure-of-arrays form, so one node
//! visit tests four boxes with SIMD lanes (`glam::Vec4`). Triangles are copied into leaf
//! order, their corners with their original index beside them.
//!
//! Two traversals read it: one ray at a time ([`Bvh::intersect_batch`], several
//! interleaved), for rays from anywhere; and a block of a texture's rays — parallel, or
//! from its centre of projection — as one beam ([`Bvh::intersect_block`], `beam.rs`),
//! for bakes and reference frames.

mod beam;
mod build;
mod triangle;

use glam::{Vec3, Vec4};

use relief_core::bounds::Aabb;
use relief_core::mesh::Mesh;

use crate::prefetch::prefetch_lines;

pub use beam::PlaneRays;
pub use triangle::intersect_triangle;

/// A 4-wide node: up to four children, each either an inner node (`count == 0`,
/// `child` = node index) or a leaf (`count` triangles from `child`). Lanes at or past
/// `len` are unused.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(64))]
pub(crate) struct Node4 {
    min_x: Vec4,
    min_y: Vec4,
    min_z: Vec4,
    max_x: Vec4,
    max_y: Vec4,
    max_z: Vec4,
    child: [u32; 4],
    count: [u32; 4],
    /// Bit `k` set when lane `k` holds a child.
    lanes: u32,
}

/// A triangle in leaf order: its corners exactly as the mesh has them, so that the
/// triangles sharing a corner agree on it to the bit (the beam's watertightness rests
/// on that; the single-ray test derives its edges on the fly).
#[derive(Debug, Clone, Copy)]
pub(crate) struct TriAccel {
    v0: Vec3,
    v1: Vec3,
    v2: Vec3,
    /// Index of the triangle in the mesh.
    id: u32,
}

/// The closest intersection along a ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter: the hit point is `origin + t · direction`.
    pub t: f32,
    /// Barycentric weights of corners 1 and 2 (corner 0 gets `1 - u - v`).
    pub u: f32,
    pub v: f32,
    /// Index of the triangle in the mesh.
    pub triangle: u32,
}

/// Traversal items are `u32`: a node index, or, with this bit set, a leaf packed as
/// `count << COUNT_SHIFT | first triangle`. Hence meshes of at most
/// [`relief_core::mesh::MAX_TRIANGLES`] triangles and leaves of at most 15.
const LEAF: u32 = 1 << 31;
const COUNT_SHIFT: u32 = 27;
const COUNT_MASK: u32 = 0xF;
const FIRST_MASK: u32 = (1 << COUNT_SHIFT) - 1;

/// The triangles of the leaf item `item`.
#[inline(always)]
fn leaf_range(item: u32) -> std::ops::Range<usize> {
    let first = (item & FIRST_MASK) as usize;
    first..first + (item >> COUNT_SHIFT & COUNT_MASK) as usize
}

/// The children of `node` whose lanes `mask` sets, as traversal items (a node index, or
/// a leaf packed by [`LEAF`]) with their near distance from `near`, farthest first: the
/// order to push them in, so that the nearest is visited first.
#[inline(always)]
fn children_farthest_first(node: &Node4, mut mask: u32, near: [f32; 4]) -> ([(u32, f32); 4], usize) {
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
        children[n] = (child, near[lane]);
        n += 1;
    }
    if n > 1 {
        children[..n].sort_unstable_by(|a, b| b.1.total_cmp(&a.1));
    }
    (children, n)
}

/// Deepest binary tree the builder makes; the 4-wide traversal stack holds three
/// entries per level.
const MAX_DEPTH: usize = 64;
const STACK: usize = 3 * MAX_DEPTH;

/// Slab distances are widened by this factor so that rounding never drops a box that a
/// triangle on its boundary is hit in (2·γ₃ of Pharr et al.).
const SLAB_WIDEN: f32 = 1.0 + 4.0 * f32::EPSILON;

/// A BVH over one mesh's triangles.
#[derive(Debug, Clone)]
pub struct Bvh {
    nodes: Vec<Node4>,
    bounds: Aabb,
    triangles: Vec<TriAccel>,
}

/// `1 / d` per axis, with zero components replaced by a tiny number of the same sign so
/// that `0 · ∞` never turns a slab distance into NaN.
#[inline]
fn safe_recip(d: Vec3) -> Vec3 {
    let tiny = |x: f32| if x.abs() < 1e-30 { 1e-30f32.copysign(x) } else { x };
    Vec3::new(tiny(d.x), tiny(d.y), tiny(d.z)).recip()
}

impl Bvh {
    /// Builds the hierarchy with binned SAH, in parallel on the current rayon pool.
    pub fn build(mesh: &Mesh) -> Bvh {
        build::build(mesh)
    }

    /// World bounds of everything in the tree.
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// Heap bytes held by the hierarchy (nodes and the reordered triangles).
    pub fn heap_bytes(&self) -> usize {
        self.nodes.capacity() * size_of::<Node4>() + self.triangles.capacity() * size_of::<TriAccel>()
    }

    /// Number of 4-wide nodes.
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The closest hit with `t` in `[t_min, t_max)`, or `None`.
    pub fn intersect(&self, origin: Vec3, direction: Vec3, t_min: f32, t_max: f32) -> Option<Hit> {
        let mut hit = [None];
        let ray = Ray {
            origin,
            direction,
            t_min,
            t_max,
        };
        self.intersect_batch(&[ray], &mut hit);
        hit[0]
    }

    /// The closest hit of every ray, written to `hits` (same length as `rays`).
    ///
    /// Several rays are traversed in lock-step, one node each in turn, each prefetching
    /// its next node: their fetches are independent, so the processor overlaps the cache
    /// misses that a single ray would wait for one after another.
    pub fn intersect_batch(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        assert_eq!(rays.len(), hits.len(), "one hit slot per ray");
        LANES.with(|lanes| {
            let mut lanes = lanes.borrow_mut();
            if lanes.is_empty() {
                lanes.resize_with(INTERLEAVE, Traversal::idle);
            }
            let mut ray_of_lane = [usize::MAX; INTERLEAVE];
            let mut next_ray = 0;
            loop {
                let mut active = false;
                for (lane, traversal) in lanes.iter_mut().enumerate() {
                    if ray_of_lane[lane] == usize::MAX {
                        if next_ray == rays.len() {
                            continue;
                        }
                        traversal.start(self, rays[next_ray]);
                        ray_of_lane[lane] = next_ray;
                        next_ray += 1;
                    }
                    active = true;
                    if !traversal.step(self) {
                        hits[ray_of_lane[lane]] = traversal.hit(self);
                        ray_of_lane[lane] = usize::MAX;
                    }
                }
                if !active {
                    return;
                }
            }
        });
    }
}

/// Rays traversed together by [`Bvh::intersect_batch`].
const INTERLEAVE: usize = 32;

thread_local! {
    /// Per-thread traversal states, kept so their stacks are not re-initialised per ray.
    static LANES: std::cell::RefCell<Vec<Traversal>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A ray and the parameter interval searched for hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
    pub t_min: f32,
    pub t_max: f32,
}

/// The state of one ray's closest-hit traversal, advanced one node at a time.
struct Traversal {
    origin: Vec3,
    direction: Vec3,
    o: [Vec4; 3],
    inv: [Vec4; 3],
    t_min: f32,
    best_t: f32,
    best: Option<(u32, f32, f32)>,
    /// What to visit next, if anything: a node index, or a leaf packed by [`LEAF`].
    item: Option<u32>,
    stack: [(u32, f32); STACK],
    depth: usize,
}

impl Traversal {
    fn idle() -> Self {
        Traversal {
            origin: Vec3::ZERO,
            direction: Vec3::ZERO,
            o: [Vec4::ZERO; 3],
            inv: [Vec4::ZERO; 3],
            t_min: 0.0,
            best_t: 0.0,
            best: None,
            item: None,
            stack: [(0, 0.0); STACK],
            depth: 0,
        }
    }

    /// Resets for a new ray (the stack's contents stay: only entries below `depth` are
    /// ever read).
    #[inline]
    fn start(&mut self, bvh: &Bvh, ray: Ray) {
        let inv = safe_recip(ray.direction);
        self.origin = ray.origin;
        self.direction = ray.direction;
        self.o = [
            Vec4::splat(ray.origin.x),
            Vec4::splat(ray.origin.y),
            Vec4::splat(ray.origin.z),
        ];
        self.inv = [Vec4::splat(inv.x), Vec4::splat(inv.y), Vec4::splat(inv.z)];
        self.t_min = ray.t_min;
        self.best_t = ray.t_max;
        self.best = None;
        self.item = (!bvh.triangles.is_empty()).then_some(0);
        self.depth = 0;
    }

    /// Visits one item — a node, or a leaf's triangles — and picks the next; false
    /// when the ray is done.
    #[inline]
    fn step(&mut self, bvh: &Bvh) -> bool {
        let Some(item) = self.item else {
            return false;
        };
        let mut next = None;
        if item & LEAF != 0 {
            let leaf = leaf_range(item);
            let first = leaf.start;
            for (k, tri) in bvh.triangles[leaf].iter().enumerate() {
                if let Some((t, u, v)) = intersect_triangle(
                    self.origin,
                    self.direction,
                    tri.v0,
                    tri.v1 - tri.v0,
                    tri.v2 - tri.v0,
                    self.t_min,
                    self.best_t,
                ) {
                    self.best_t = t;
                    self.best = Some(((first + k) as u32, u, v));
                }
            }
        } else {
            let node = &bvh.nodes[item as usize];
            let [ox, oy, oz] = self.o;
            let [ix, iy, iz] = self.inv;
            let (ax, bx) = ((node.min_x - ox) * ix, (node.max_x - ox) * ix);
            let (ay, by) = ((node.min_y - oy) * iy, (node.max_y - oy) * iy);
            let (az, bz) = ((node.min_z - oz) * iz, (node.max_z - oz) * iz);
            let near = ax
                .min(bx)
                .max(ay.min(by))
                .max(az.min(bz))
                .max(Vec4::splat(self.t_min));
            let far = (ax.max(bx).min(ay.max(by)).min(az.max(bz)) * SLAB_WIDEN).min(Vec4::splat(self.best_t));
            let mask = near.cmple(far).bitmask() & node.lanes;
            let (children, n) = children_farthest_first(node, mask, near.to_array());
            // Nearest child next; the others onto the stack, farthest first.
            for &child in &children[..n] {
                if let Some(pending) = next.replace(child) {
                    self.stack[self.depth] = pending;
                    self.depth += 1;
                }
            }
        }
        self.item = next.map(|(child, _)| child);
        if self.item.is_none() {
            // Pop the next item that can still hold a closer hit.
            while self.depth > 0 {
                self.depth -= 1;
                let (item, t_entry) = self.stack[self.depth];
                if t_entry <= self.best_t {
                    self.item = Some(item);
                    break;
                }
            }
        }
        // Start fetching what the next step reads; in a batch, other rays run while it
        // arrives.
        match self.item {
            Some(item) if item & LEAF != 0 => {
                prefetch_lines(&bvh.triangles[leaf_range(item)]);
                true
            }
            Some(item) => {
                prefetch_lines(std::slice::from_ref(&bvh.nodes[item as usize]));
                true
            }
            None => false,
        }
    }

    fn hit(&self, bvh: &Bvh) -> Option<Hit> {
        self.best.map(|(k, u, v)| Hit {
            t: self.best_t,
            u,
            v,
            triangle: bvh.triangles[k as usize].id,
        })
    }
}

#[cfg(test)]
mod tests;
