//! Binned-SAH construction, parallel over subtrees.
//!
//! Each split bins triangle centroids into [`BINS`] slots along all three axes and takes
//! the plane of least surface-area-heuristic cost; a node becomes a leaf when splitting
//! costs more than intersecting its triangles. Below [`SAH_DEPTH`] levels the builder
//! switches to median splits, which halve the count and so bound the depth by
//! [`super::MAX_DEPTH`].

use glam::Vec3;
use rayon::join;

use relief_core::bounds::Aabb;
use relief_core::mesh::Mesh;

use glam::Vec4;

use super::{Bvh, Node4, TriAccel};

const BINS: usize = 16;
/// Largest leaf; bigger nodes are always split.
const MAX_LEAF: usize = 8;
/// Relative cost of one node visit against one triangle test.
const TRAVERSAL_COST: f32 = 2.0;
/// Subtrees smaller than this are built on the current thread.
const PARALLEL_MIN: usize = 8 * 1024;
/// SAH splits up to this depth, median splits below: depth ≤ 24 + 32 < 64.
const SAH_DEPTH: usize = 24;

#[derive(Clone, Copy)]
struct PrimRef {
    bounds: Aabb,
    centroid: Vec3,
}

enum BuildNode {
    Leaf {
        bounds: Aabb,
        first: u32,
        count: u32,
    },
    Interior {
        bounds: Aabb,
        children: Box<[BuildNode; 2]>,
    },
}

impl BuildNode {
    fn bounds(&self) -> Aabb {
        match self {
            BuildNode::Leaf { bounds, .. } | BuildNode::Interior { bounds, .. } => *bounds,
        }
    }
}

pub(super) fn build(mesh: &Mesh) -> Bvh {
    use rayon::prelude::*;
    let refs: Vec<PrimRef> = (0..mesh.triangle_count())
        .into_par_iter()
        .map(|t| {
            let bounds = Aabb::from_points(mesh.corners(t));
            PrimRef {
                bounds,
                centroid: bounds.center(),
            }
        })
        .collect();
    let mut order: Vec<u32> = (0..refs.len() as u32).collect();
    let (bounds, centroids) = span(&refs, &order);
    let root = if order.is_empty() {
        BuildNode::Leaf {
            bounds: Aabb {
                min: Vec3::ZERO,
                max: Vec3::ZERO,
            },
            first: 0,
            count: 0,
        }
    } else {
        subdivide(&refs, &mut order, 0, bounds, centroids, 0)
    };
    let bounds = root.bounds();
    let mut nodes = Vec::with_capacity(refs.len() / 6 + 1);
    collapse(&root, &mut nodes);
    nodes.shrink_to_fit();
    drop(root);
    let triangles = order
        .par_iter()
        .map(|&t| {
            let [a, b, c] = mesh.corners(t as usize);
            TriAccel {
                v0: a,
                v1: b,
                v2: c,
                id: t,
            }
        })
        .collect();
    Bvh {
        nodes,
        bounds,
        triangles,
    }
}

/// Bounds of the primitives and of their centroids.
fn span(refs: &[PrimRef], prims: &[u32]) -> (Aabb, Aabb) {
    let mut bounds = Aabb::EMPTY;
    let mut centroids = Aabb::EMPTY;
    for &p in prims {
        let r = &refs[p as usize];
        bounds = bounds.union(r.bounds);
        centroids.grow(r.centroid);
    }
    (bounds, centroids)
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    centroids: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin {
    bounds: Aabb::EMPTY,
    centroids: Aabb::EMPTY,
    count: 0,
};

/// The split chosen for a node: axis, first bin of the right side, and both sides'
/// bounds.
struct Split {
    axis: usize,
    bin: usize,
    left: (Aabb, Aabb),
    right: (Aabb, Aabb),
}

/// Builds the subtree over `prims` (which start at `offset` in the final order).
fn subdivide(
    refs: &[PrimRef],
    prims: &mut [u32],
    offset: u32,
    bounds: Aabb,
    centroids: Aabb,
    depth: usize,
) -> BuildNode {
    let n = prims.len();
    let leaf = BuildNode::Leaf {
        bounds,
        first: offset,
        count: n as u32,
    };
    if n <= 2 {
        return leaf;
    }
    let (mid, left, right) = if depth < SAH_DEPTH {
        match best_split(refs, prims, bounds, centroids) {
            Some((split, cost)) => {
                let leaf_cost = n as f32 * bounds.half_area();
                if n <= MAX_LEAF && leaf_cost <= cost {
                    return leaf;
                }
                let mid = partition(refs, prims, centroids, split.axis, split.bin);
                (mid, split.left, split.right)
            }
            None if n <= MAX_LEAF => return leaf,
            None => median_split(refs, prims, centroids),
        }
    } else if n <= MAX_LEAF {
        return leaf;
    } else {
        median_split(refs, prims, centroids)
    };
    let (lp, rp) = prims.split_at_mut(mid);
    let mut build_left = || subdivide(refs, lp, offset, left.0, left.1, depth + 1);
    let mut build_right = || subdivide(refs, rp, offset + mid as u32, right.0, right.1, depth + 1);
    let (l, r) = if n >= PARALLEL_MIN {
        join(build_left, build_right)
    } else {
        (build_left(), build_right())
    };
    BuildNode::Interior {
        bounds,
        children: Box::new([l, r]),
    }
}

#[inline]
fn bin_of(centroid: f32, lo: f32, scale: f32) -> usize {
    (((centroid - lo) * scale) as usize).min(BINS - 1)
}

/// Evaluates SAH over binned planes on all three axes; `None` when every centroid
/// coincides. Costs are in units of `half_area × triangle tests`.
fn best_split(refs: &[PrimRef], prims: &[u32], bounds: Aabb, centroids: Aabb) -> Option<(Split, f32)> {
    let extent = centroids.extent();
    let mut bins = [[EMPTY_BIN; BINS]; 3];
    let scale = Vec3::select(
        extent.cmpgt(Vec3::ZERO),
        Vec3::splat(BINS as f32 * (1.0 - 1e-6)) / extent,
        Vec3::ZERO,
    );
    for &p in prims {
        let r = &refs[p as usize];
        for axis in 0..3 {
            let b = &mut bins[axis][bin_of(r.centroid[axis], centroids.min[axis], scale[axis])];
            b.bounds = b.bounds.union(r.bounds);
            b.centroids.grow(r.centroid);
            b.count += 1;
        }
    }
    let mut best: Option<(Split, f32)> = None;
    for (axis, bins) in bins.iter().enumerate() {
        if extent[axis] <= 0.0 {
            continue;
        }
        // Right-to-left sweep: cost of the right side for each plane.
        let mut right_area = [0f32; BINS];
        let mut right_count = [0u32; BINS];
        let mut acc = EMPTY_BIN;
        for k in (1..BINS).rev() {
            acc = merge(acc, bins[k]);
            right_area[k] = acc.bounds.half_area();
            right_count[k] = acc.count;
        }
        let mut left = EMPTY_BIN;
        for k in 1..BINS {
            left = merge(left, bins[k - 1]);
            if left.count == 0 || right_count[k] == 0 {
                continue;
            }
            let cost = TRAVERSAL_COST * bounds.half_area()
                + left.bounds.half_area() * left.count as f32
                + right_area[k] * right_count[k] as f32;
            if best.as_ref().is_none_or(|(_, c)| cost < *c) {
                let right = bins[k..].iter().fold(EMPTY_BIN, |a, &b| merge(a, b));
                best = Some((
                    Split {
                        axis,
                        bin: k,
                        left: (left.bounds, left.centroids),
                        right: (right.bounds, right.centroids),
                    },
                    cost,
                ));
            }
        }
    }
    best
}

fn merge(a: Bin, b: Bin) -> Bin {
    Bin {
        bounds: a.bounds.union(b.bounds),
        centroids: a.centroids.union(b.centroids),
        count: a.count + b.count,
    }
}

/// Moves primitives whose centroid bins below `bin` on `axis` to the front; returns
/// how many.
fn partition(refs: &[PrimRef], prims: &mut [u32], centroids: Aabb, axis: usize, bin: usize) -> usize {
    let extent = centroids.extent()[axis];
    let scale = BINS as f32 * (1.0 - 1e-6) / extent;
    let lo = centroids.min[axis];
    let mut i = 0;
    let mut j = prims.len();
    while i < j {
        if bin_of(refs[prims[i] as usize].centroid[axis], lo, scale) < bin {
            i += 1;
        } else {
            j -= 1;
            prims.swap(i, j);
        }
    }
    i
}

/// Splits at the median centroid along the widest axis (order by index when all
/// centroids coincide).
fn median_split(refs: &[PrimRef], prims: &mut [u32], centroids: Aabb) -> (usize, (Aabb, Aabb), (Aabb, Aabb)) {
    let axis = centroids.widest_axis();
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |&a, &b| {
        refs[a as usize].centroid[axis].total_cmp(&refs[b as usize].centroid[axis])
    });
    let (l, r) = prims.split_at(mid);
    (mid, span(refs, l), span(refs, r))
}

/// Appends the 4-wide node for the subtree `node` (and, depth-first, its descendants);
/// returns its index. Each 4-wide node takes its binary node's grandchildren: the inner
/// child of largest area is opened until there are four children or only leaves.
fn collapse(node: &BuildNode, nodes: &mut Vec<Node4>) -> u32 {
    let mut children: Vec<&BuildNode> = match node {
        BuildNode::Leaf { .. } => vec![node],
        BuildNode::Interior { children, .. } => vec![&children[0], &children[1]],
    };
    while children.len() < 4 {
        let widest = children
            .iter()
            .enumerate()
            .filter(|(_, c)| matches!(c, BuildNode::Interior { .. }))
            .max_by(|a, b| a.1.bounds().half_area().total_cmp(&b.1.bounds().half_area()))
            .map(|(k, _)| k);
        let Some(k) = widest else { break };
        let BuildNode::Interior { children: pair, .. } = children[k] else {
            break;
        };
        children[k] = &pair[0];
        children.push(&pair[1]);
    }
    let at = nodes.len();
    let zero = Vec4::ZERO;
    nodes.push(Node4 {
        min_x: zero,
        min_y: zero,
        min_z: zero,
        max_x: zero,
        max_y: zero,
        max_z: zero,
        child: [0; 4],
        count: [0; 4],
        lanes: 0,
    });
    let mut lanes = [(Aabb::EMPTY, 0u32, 0u32); 4];
    for (lane, child) in children.iter().enumerate() {
        lanes[lane] = match child {
            BuildNode::Leaf { bounds, first, count } => (*bounds, *first, *count),
            BuildNode::Interior { bounds, .. } => (*bounds, collapse(child, nodes), 0),
        };
    }
    let pick = |f: &dyn Fn(&Aabb) -> f32| {
        Vec4::from_array(std::array::from_fn(|k| {
            if k < children.len() { f(&lanes[k].0) } else { 0.0 }
        }))
    };
    nodes[at] = Node4 {
        min_x: pick(&|b| b.min.x),
        min_y: pick(&|b| b.min.y),
        min_z: pick(&|b| b.min.z),
        max_x: pick(&|b| b.max.x),
        max_y: pick(&|b| b.max.y),
        max_z: pick(&|b| b.max.z),
        child: lanes.map(|l| l.1),
        count: lanes.map(|l| l.2),
        lanes: (1u32 << children.len()) - 1,
    };
    at as u32
}
