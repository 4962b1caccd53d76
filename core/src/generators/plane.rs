//! A flat square grid, the ground of the built-in scenes.

use glam::Vec3;

use crate::mesh::{Material, Mesh};

pub(super) fn plane(size: f32, divisions: u32) -> Mesh {
    let n = divisions as usize;
    let mut positions = Vec::with_capacity((n + 1) * (n + 1));
    for j in 0..=n {
        for i in 0..=n {
            let x = (i as f32 / n as f32 - 0.5) * size;
            let z = (j as f32 / n as f32 - 0.5) * size;
            positions.push(Vec3::new(x, 0.0, z));
        }
    }
    let index = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    let mut triangles = Vec::with_capacity(2 * n * n);
    for j in 0..n {
        for i in 0..n {
            // Winding chosen so that (b - a) × (c - a) points to +y.
            triangles.push([index(i, j), index(i, j + 1), index(i + 1, j + 1)]);
            triangles.push([index(i, j), index(i + 1, j + 1), index(i + 1, j)]);
        }
    }
    Mesh {
        normals: Some(vec![Vec3::Y; positions.len()]),
        positions,
        triangles,
        materials: vec![Material::default()],
        ..Default::default()
    }
}
