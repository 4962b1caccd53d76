//! Near-plane clipping in view space, then projection to pixels.

use glam::{Vec2, Vec3};

use relief_core::camera::Camera;

/// A projected triangle: pixel positions, view depths, and barycentric positions in the
/// original triangle.
pub(super) type Projected = ([Vec2; 3], [f32; 3], [Vec2; 3]);

/// Clips the view-space triangle `v` against `depth >= near` (Sutherland–Hodgman on one
/// plane: 0, 1 or 2 triangles) and projects the pieces.
pub(super) fn clip_and_project(camera: &Camera, near: f32, v: [Vec3; 3]) -> Vec<Projected> {
    // Barycentric (u, v) of the original corners: weights of corners 1 and 2.
    const CORNERS: [Vec2; 3] = [Vec2::ZERO, Vec2::X, Vec2::Y];
    let inside = v.map(|p| p.z >= near);
    if !v.iter().all(|p| p.is_finite()) || inside.iter().all(|&i| !i) {
        return Vec::new();
    }
    let project = |p: Vec3, bary: Vec2| {
        let (x, y) = camera.view_to_pixel(p);
        (Vec2::new(x, y), p.z, bary)
    };
    if inside.iter().all(|&i| i) {
        let [a, b, c] = [0, 1, 2].map(|k| project(v[k], CORNERS[k]));
        return vec![([a.0, b.0, c.0], [a.1, b.1, c.1], [a.2, b.2, c.2])];
    }
    let mut polygon: Vec<(Vec3, Vec2)> = Vec::with_capacity(4);
    for k in 0..3 {
        let (p, q) = ((v[k], CORNERS[k]), (v[(k + 1) % 3], CORNERS[(k + 1) % 3]));
        if inside[k] {
            polygon.push(p);
        }
        if inside[k] != inside[(k + 1) % 3] {
            let t = (near - p.0.z) / (q.0.z - p.0.z);
            polygon.push((p.0.lerp(q.0, t), p.1.lerp(q.1, t)));
        }
    }
    let projected: Vec<_> = polygon.into_iter().map(|(p, b)| project(p, b)).collect();
    (1..projected.len() - 1)
        .map(|k| {
            let (a, b, c) = (projected[0], projected[k], projected[k + 1]);
            ([a.0, b.0, c.0], [a.1, b.1, c.1], [a.2, b.2, c.2])
        })
        .collect()
}
