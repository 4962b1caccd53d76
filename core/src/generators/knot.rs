//! A tube around a (p, q) torus knot.

use std::f32::consts::TAU;

use glam::Vec3;

use crate::mesh::{Material, Mesh};

/// The knot's centre line, scaled so the tube fits in the unit ball.
fn centre_line(p: f32, q: f32, phi: f32, scale: f32) -> Vec3 {
    let r = 2.0 + (q * phi).cos();
    Vec3::new(r * (p * phi).cos(), r * (p * phi).sin(), (q * phi).sin()) * scale
}

pub(super) fn torus_knot(p: u32, q: u32, segments: u32, sides: u32, tube_radius: f32) -> Mesh {
    let (pf, qf) = (p as f32, q as f32);
    // The centre line reaches radius 3; leave room for the tube.
    let scale = (1.0 - tube_radius) / 3.0;
    let (n, m) = (segments as usize, sides as usize);
    let mut positions = Vec::with_capacity(n * m);
    let mut normals = Vec::with_capacity(n * m);
    for i in 0..n {
        let phi = i as f32 / n as f32 * TAU;
        let centre = centre_line(pf, qf, phi, scale);
        let tangent =
            (centre_line(pf, qf, phi + 1e-3, scale) - centre_line(pf, qf, phi - 1e-3, scale)).normalize();
        // The tangent always has an xy component (|d(xy)/dφ| ≥ p·r > 0), so crossing
        // with z gives a smooth, periodic frame with no twist seam.
        let n1 = tangent.cross(Vec3::Z).normalize();
        let n2 = n1.cross(tangent);
        for j in 0..m {
            let theta = j as f32 / m as f32 * TAU;
            let radial = n1 * theta.cos() + n2 * theta.sin();
            positions.push(centre + radial * tube_radius);
            normals.push(radial);
        }
    }
    let index = |i: usize, j: usize| ((i % n) * m + (j % m)) as u32;
    let mut triangles = Vec::with_capacity(2 * n * m);
    for i in 0..n {
        for j in 0..m {
            let (a, b, c, d) = (index(i, j), index(i + 1, j), index(i + 1, j + 1), index(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    let mut mesh = Mesh {
        positions,
        normals: Some(normals),
        triangles,
        materials: vec![Material::default()],
        ..Default::default()
    };
    orient_outwards(&mut mesh);
    mesh
}

/// Flips the winding if it disagrees with the vertex normals (the frame's handedness
/// depends on p and q).
fn orient_outwards(mesh: &mut Mesh) {
    let normals = mesh
        .normals
        .as_ref()
        .map_or(Vec3::ZERO, |ns| ns[mesh.triangles[0][0] as usize]);
    if mesh.face_normal(0).dot(normals) < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
}
