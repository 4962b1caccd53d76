//! Near-plane clipping in view space, then projection to pixels.

use glam::{Vec2, Vec3};

use relief_core::camera::Projection;

/// A projected triangle: pixel positions, view depths, and barycentric positions in the
/// original triangle.
pub(super) type Projected = ([Vec2; 3], [f32; 3], [Vec2; 3]);

/// A triangle corner: its view-space position and, when in front of the near plane, its
/// pixel position (projected once per vertex, shared by the triangles around it).
#[derive(Debug, Clone, Copy)]
pub(super) struct Corner {
    pub view: Vec3,
    pub pixel: Vec2,
}

impl Corner {
    pub fn new(projection: &Projection, view: Vec3) -> Corner {
        let (x, y) = projection.view_to_pixel(view);
        Corner {
            view,
            pixel: Vec2::new(x, y),
        }
    }
}

/// What is left of a triangle after clipping: none, one or two projected triangles.
pub(super) struct Clipped {
    pieces: [Projected; 2],
    count: usize,
}

impl Clipped {
    const NONE: Clipped = Clipped {
        pieces: [([Vec2::ZERO; 3], [0.0; 3], [Vec2::ZERO; 3]); 2],
        count: 0,
    };

    pub fn into_iter(self) -> impl Iterator<Item = Projected> {
        self.pieces.into_iter().take(self.count)
    }
}

/// Clips the triangle `corners` against `depth >= near` (Sutherland–Hodgman on one
/// plane: 0, 1 or 2 triangles) and projects the pieces. Allocates nothing: it runs for
/// every triangle of every frame drawn as geometry.
pub(super) fn clip_and_project(projection: &Projection, near: f32, corners: [Corner; 3]) -> Clipped {
    // Barycentric (u, v) of the original corners: weights of corners 1 and 2.
    const BARY: [Vec2; 3] = [Vec2::ZERO, Vec2::X, Vec2::Y];
    let v = corners.map(|c| c.view);
    let inside = v.map(|p| p.z >= near);
    if !v.iter().all(|p| p.is_finite()) || inside.iter().all(|&i| !i) {
        return Clipped::NONE;
    }
    if inside.iter().all(|&i| i) {
        let mut clipped = Clipped::NONE;
        clipped.pieces[0] = (corners.map(|c| c.pixel), v.map(|p| p.z), BARY);
        clipped.count = 1;
        return clipped;
    }
    // The clipped polygon: 3 or 4 corners.
    let mut polygon = [(Vec2::ZERO, 0.0f32, Vec2::ZERO); 4];
    let mut n = 0;
    let mut push = |p: Vec3, bary: Vec2| {
        let (x, y) = projection.view_to_pixel(p);
        polygon[n] = (Vec2::new(x, y), p.z, bary);
        n += 1;
    };
    for k in 0..3 {
        let l = (k + 1) % 3;
        if inside[k] {
            push(v[k], BARY[k]);
        }
        if inside[k] != inside[l] {
            let t = (near - v[k].z) / (v[l].z - v[k].z);
            push(v[k].lerp(v[l], t), BARY[k].lerp(BARY[l], t));
        }
    }
    let mut clipped = Clipped::NONE;
    for k in 1..n - 1 {
        let (a, b, c) = (polygon[0], polygon[k], polygon[k + 1]);
        clipped.pieces[k - 1] = ([a.0, b.0, c.0], [a.1, b.1, c.1], [a.2, b.2, c.2]);
    }
    clipped.count = n - 2;
    clipped
}
