//! The top level of a scene's two-level BVH: a binary tree over its objects' bounds in
//! the world. The bottom level is each mesh's own [`Bvh`](crate::bvh::Bvh), in the
//! mesh's frame, shared by every placement of it ([`ObjectTracer::all`]).
//!
//! A reference frame walks it once per block of pixels ([`Placements::nearest_first`]):
//! only the objects whose bounds reach into the block's rays ([`BlockRays`]), nearest
//! first, and none whose bounds lie wholly behind what the block's samples already hit.
//! In a wood of hundreds of placements a block meets a few trees, and the near ones hide
//! the rest.
//!
//! [`ObjectTracer::all`]: crate::tracer::ObjectTracer::all

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::{DVec3, Vec3};

use relief_core::bounds::Aabb;
use relief_core::camera::Camera;

/// Objects a leaf holds at most: a block tests a leaf's boxes one by one, where a split
/// costs a node more on every walk.
const LEAF_OBJECTS: usize = 2;

/// A node: a leaf holds `count` objects from `first` in [`Placements::order`]; an inner
/// node (`count == 0`) has its two children at `first` and `first + 1`.
#[derive(Debug, Clone, Copy)]
struct Node {
    bounds: Aabb,
    first: u32,
    count: u32,
}

/// A BVH over the world bounds of a scene's objects (the top level).
#[derive(Debug, Clone)]
pub struct Placements {
    nodes: Vec<Node>,
    /// Object indices in leaf order.
    order: Vec<u32>,
    /// Object `k`'s world bounds.
    bounds: Vec<Aabb>,
}

impl Placements {
    /// Builds the tree over `bounds`, object `k`'s world bounds at `bounds[k]`: each
    /// node split at the median of its objects' centres along the longest axis of those
    /// centres' bounds.
    pub fn build(bounds: &[Aabb]) -> Placements {
        let mut order: Vec<u32> = (0..bounds.len() as u32).collect();
        let union = |objects: &[u32]| {
            objects
                .iter()
                .fold(Aabb::default(), |b, &k| b.union(bounds[k as usize]))
        };
        let mut nodes = vec![Node {
            bounds: Aabb::default(),
            first: 0,
            count: 0,
        }];
        // (node, its objects' range in `order`)
        let mut work = vec![(0usize, 0usize, order.len())];
        while let Some((node, start, end)) = work.pop() {
            let objects = &mut order[start..end];
            nodes[node].bounds = union(objects);
            if objects.len() <= LEAF_OBJECTS {
                (nodes[node].first, nodes[node].count) = (start as u32, objects.len() as u32);
                continue;
            }
            let centres = Aabb::from_points(objects.iter().map(|&k| bounds[k as usize].center()));
            let axis = centres.widest_axis();
            let middle = objects.len() / 2;
            objects.select_nth_unstable_by(middle, |&a, &b| {
                let (a, b) = (bounds[a as usize].center(), bounds[b as usize].center());
                a[axis].total_cmp(&b[axis])
            });
            let children = nodes.len();
            nodes[node].first = children as u32;
            nodes.extend([nodes[node]; 2]);
            work.push((children, start, start + middle));
            work.push((children + 1, start + middle, end));
        }
        Placements {
            nodes,
            order,
            bounds: bounds.to_vec(),
        }
    }

    /// Calls `visit(k)` for each object `k` whose bounds reach into `rays`, nearest
    /// first by the near depth of its bounds along the view axis. `visit` returns the
    /// view depth past which nothing more can matter (the farthest of the block's
    /// nearest hits, infinite while a sample has none); objects whose bounds begin
    /// beyond it (by more than [`DEPTH_MARGIN`]) are not visited. Whatever the order,
    /// the block's nearest hits are those of every object: a caller that breaks ties
    /// between objects by index draws what tracing each object in turn draws.
    pub fn nearest_first(&self, rays: &BlockRays, mut visit: impl FnMut(usize) -> f32) {
        if self.order.is_empty() {
            return;
        }
        let mut beyond = f32::INFINITY;
        let past = |near: f32, beyond: f32| near > beyond * (1.0 + DEPTH_MARGIN);
        let mut queue = BinaryHeap::new();
        if let Some(near) = rays.near_depth(&self.nodes[0].bounds) {
            queue.push(Nearest { near, node: 0 });
        }
        while let Some(Nearest { near, node }) = queue.pop() {
            if past(near, beyond) {
                break;
            }
            let Node { first, count, .. } = self.nodes[node as usize];
            if count == 0 {
                for child in [first, first + 1] {
                    if let Some(near) = rays.near_depth(&self.nodes[child as usize].bounds) {
                        queue.push(Nearest { near, node: child });
                    }
                }
                continue;
            }
            // A leaf's objects, nearest first.
            let mut objects: Vec<(f32, u32)> = (self.order[first as usize..(first + count) as usize].iter())
                .filter_map(|&k| Some((rays.near_depth(&self.bounds[k as usize])?, k)))
                .collect();
            objects.sort_by(|a, b| a.0.total_cmp(&b.0));
            for (near, k) in objects {
                if !past(near, beyond) {
                    beyond = visit(k as usize);
                }
            }
        }
    }
}

/// A node waiting in [`Placements::nearest_first`]'s queue, the nearest on top.
#[derive(Debug, Clone, Copy)]
struct Nearest {
    near: f32,
    node: u32,
}

impl PartialEq for Nearest {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Nearest {}
impl PartialOrd for Nearest {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Nearest {
    fn cmp(&self, other: &Self) -> Ordering {
        other.near.total_cmp(&self.near).then(other.node.cmp(&self.node))
    }
}

/// Relative margin on the depth test of [`Placements::nearest_first`]: a hit's depth
/// (traced in its object's frame, scaled into the world) and its bounds' near depth
/// (from the world bounds, rounded outwards to `f32`) round differently, by a few
/// units in the last place.
pub const DEPTH_MARGIN: f32 = 1e-4;

/// Relative margin on the side tests of [`BlockRays`]: a box is outside a plane only
/// when it is farther out than rounding can explain.
pub const SIDE_MARGIN: f32 = 1e-5;

/// The rays of one eye through a rectangle of pixels: the four planes through the eye
/// and the rectangle's edges (their normals pointing inwards), and the view axis.
#[derive(Debug, Clone, Copy)]
pub struct BlockRays {
    eye: DVec3,
    forward: Vec3,
    sides: [Vec3; 4],
}

impl BlockRays {
    /// The rays of `camera` (in the world) through the pixel positions from `(x0, y0)`
    /// to `(x1, y1)`, as [`Camera::ray`] takes them.
    pub fn new(camera: &Camera, (x0, y0): (f32, f32), (x1, y1): (f32, f32)) -> BlockRays {
        let corners = [
            camera.ray(x0, y0),
            camera.ray(x1, y0),
            camera.ray(x1, y1),
            camera.ray(x0, y1),
        ];
        let middle = camera.ray(0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let sides = std::array::from_fn(|i| {
            let normal = corners[i].cross(corners[(i + 1) % 4]);
            if normal.dot(middle) < 0.0 { -normal } else { normal }
        });
        BlockRays {
            eye: camera.eye,
            forward: camera.forward,
            sides,
        }
    }

    /// The least view depth of the world box `bounds`, or `None` when the box lies
    /// wholly outside the rays: past a side, or behind the eye. (Coordinates are taken
    /// relative to the eye in `f64` first, so a scene far from the origin culls as
    /// finely as one at it.)
    fn near_depth(&self, bounds: &Aabb) -> Option<f32> {
        let lo = (bounds.min.as_dvec3() - self.eye).as_vec3();
        let hi = (bounds.max.as_dvec3() - self.eye).as_vec3();
        let size = lo.abs().max(hi.abs()).max_element();
        let farthest = |n: Vec3| n.dot(Vec3::select(n.cmpgt(Vec3::ZERO), hi, lo));
        let outside = |n: Vec3| farthest(n) < -SIDE_MARGIN * size * n.length();
        if self.sides.iter().any(|&n| outside(n)) || outside(self.forward) {
            return None;
        }
        let f = self.forward;
        let near = f.dot(Vec3::select(f.cmpgt(Vec3::ZERO), lo, hi));
        // (A box that cannot be placed, NaN, comes first: never culled on a doubt.)
        Some(if near.is_nan() { f32::NEG_INFINITY } else { near })
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    /// Every box one of a block's rays passes through is visited (checked ray by ray
    /// against 500 scattered boxes, far from the origin too), nothing when there are
    /// no boxes, and a box behind the eye never.
    #[test]
    fn every_box_the_rays_reach_is_visited() {
        for origin in [DVec3::ZERO, DVec3::new(-3e6, 1e5, 2e6)] {
            let mut seed = 7u32;
            let mut next = || {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (seed >> 8) as f32 / (1 << 24) as f32
            };
            let boxes: Vec<Aabb> = (0..500)
                .map(|_| {
                    let centre = Vec3::new(next() * 40.0 - 20.0, next() * 6.0, next() * 40.0 - 20.0);
                    let half = Vec3::new(next(), next(), next()) * 0.8 + 0.05;
                    Aabb {
                        min: (origin + (centre - half).as_dvec3()).as_vec3(),
                        max: (origin + (centre + half).as_dvec3()).as_vec3(),
                    }
                })
                .collect();
            let placements = Placements::build(&boxes);
            let mut camera = Camera::look_at(Vec3::ZERO, Vec3::new(0.3, -0.2, -1.0), Vec3::Y, 60.0, 64, 48)
                .expect("camera");
            camera.eye = origin + DVec3::new(0.5, 2.0, 12.0);
            for (x0, y0) in [(0, 0), (24, 16), (56, 40)] {
                let (x1, y1) = (x0 + 8, y0 + 8);
                let rays = BlockRays::new(&camera, (x0 as f32, y0 as f32), (x1 as f32, y1 as f32));
                let mut visited = vec![false; boxes.len()];
                placements.nearest_first(&rays, |k| {
                    visited[k] = true;
                    f32::INFINITY
                });
                for (k, b) in boxes.iter().enumerate() {
                    let lo = (b.min.as_dvec3() - camera.eye).as_vec3();
                    let hi = (b.max.as_dvec3() - camera.eye).as_vec3();
                    let local = Aabb { min: lo, max: hi };
                    let reached = (0..=16).any(|i| {
                        (0..=16).any(|j| {
                            let x = x0 as f32 + 8.0 * i as f32 / 16.0;
                            let y = y0 as f32 + 8.0 * j as f32 / 16.0;
                            let d = camera.ray(x, y);
                            local
                                .ray_interval(Vec3::ZERO, d.recip(), 0.0, f32::INFINITY)
                                .is_some()
                        })
                    });
                    assert!(
                        !reached || visited[k],
                        "box {k} reached at ({x0}, {y0}) but not visited"
                    );
                    let behind = camera
                        .forward
                        .dot(Vec3::select(camera.forward.cmpgt(Vec3::ZERO), hi, lo))
                        < 0.0;
                    assert!(!(behind && visited[k]), "box {k} behind the eye visited");
                }
                assert!(visited.iter().any(|&v| v), "nothing visited at ({x0}, {y0})");
                assert!(
                    visited.iter().filter(|&&v| v).count() < boxes.len() / 4,
                    "too many visited"
                );
            }
        }
        let none = Placements::build(&[]);
        let rays = BlockRays::new(
            &Camera::look_at(Vec3::ZERO, Vec3::NEG_Z, Vec3::Y, 60.0, 8, 8).expect("camera"),
            (0.0, 0.0),
            (8.0, 8.0),
        );
        none.nearest_first(&rays, |_| panic!("no object to visit"));
    }
}
