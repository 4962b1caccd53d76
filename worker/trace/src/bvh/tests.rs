//! The BVH's edge cases. Its agreement with an independent ray caster over random and
//! generated meshes is `tests/tests/bvh_oracle.rs`.

use glam::Vec3;

use relief_core::mesh::{Material, Mesh};

use super::Bvh;

#[test]
fn empty_and_single_triangle_meshes() {
    let empty = Mesh {
        materials: vec![Material::default()],
        ..Default::default()
    };
    assert!(
        Bvh::build(&empty)
            .intersect(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY)
            .is_none()
    );
    let one = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        triangles: vec![[0, 1, 2]],
        materials: vec![Material::default()],
        ..Default::default()
    };
    let hit = Bvh::build(&one)
        .intersect(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z, 0.0, f32::INFINITY)
        .unwrap();
    assert!((hit.t - 1.0).abs() < 1e-6 && (hit.u - 0.25).abs() < 1e-6 && (hit.v - 0.25).abs() < 1e-6);
    // Parallel to the plane of the triangle: no hit, no NaN.
    assert!(
        Bvh::build(&one)
            .intersect(Vec3::new(-1.0, 0.2, 0.0), Vec3::X, 0.0, f32::INFINITY)
            .is_none()
    );
}

#[test]
fn deep_degenerate_input_stays_within_the_stack() {
    // Many triangles with the same centroid force the median fallback.
    let mut mesh = Mesh {
        materials: vec![Material::default()],
        ..Default::default()
    };
    for k in 0..5000 {
        let s = 1.0 + k as f32 * 1e-4;
        let base = mesh.positions.len() as u32;
        mesh.positions.extend([
            Vec3::new(-s, -s, 0.0),
            Vec3::new(s, -s, 0.0),
            Vec3::new(0.0, 2.0 * s, 0.0),
        ]);
        mesh.triangles.push([base, base + 1, base + 2]);
    }
    let bvh = Bvh::build(&mesh);
    let hit = bvh.intersect(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z, 0.0, f32::INFINITY);
    assert!(hit.is_some_and(|h| (h.t - 1.0).abs() < 1e-6));
}
