//! The BVH against brute force over every triangle.

use glam::Vec3;

use relief_core::generators::Generator;
use relief_core::mesh::{Material, Mesh};

use super::{Bvh, intersect_brute_force};

/// xorshift64*: deterministic test randomness.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }

    fn vec(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * 2.0 * scale - Vec3::splat(scale)
    }
}

/// Random triangles in a cube, some tiny, some degenerate, some sharing corners.
fn random_mesh(rng: &mut Rng, count: usize) -> Mesh {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for k in 0..count {
        let centre = rng.vec(1.0);
        let size = if k % 7 == 0 { 0.01 } else { 0.3 };
        let a = centre + rng.vec(size);
        let b = centre + rng.vec(size);
        let c = match k % 11 {
            0 => b,                 // degenerate: two equal corners
            1 => a + (b - a) * 0.5, // degenerate: collinear
            _ => centre + rng.vec(size),
        };
        let base = positions.len() as u32;
        positions.extend([a, b, c]);
        triangles.push([base, base + 1, base + 2]);
        if k % 5 == 0 && k > 0 {
            // A triangle reusing the previous one's corners (shared edges).
            triangles.push([base - 1, base, base + 2]);
        }
    }
    Mesh {
        positions,
        triangles,
        materials: vec![Material::default()],
        ..Default::default()
    }
}

fn assert_agrees(mesh: &Mesh, bvh: &Bvh, origin: Vec3, direction: Vec3, t_max: f32) {
    let got = bvh.intersect(origin, direction, 0.0, t_max);
    let want = intersect_brute_force(mesh, origin, direction, 0.0, t_max);
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) => {
            let tolerance = 1e-5 * w.t.abs().max(1e-6);
            assert!(
                (g.t - w.t).abs() <= tolerance,
                "t {} vs {} for {origin} {direction}",
                g.t,
                w.t
            );
            if g.triangle != w.triangle {
                // Only a tie (a shared edge or coplanar overlap) may pick another triangle.
                assert!((g.t - w.t).abs() <= tolerance);
            }
        }
        _ => panic!("hit/miss differ: bvh {got:?}, brute force {want:?}, ray {origin} {direction}"),
    }
}

#[test]
fn random_meshes_match_brute_force() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for (round, count) in [1usize, 2, 3, 9, 40, 300, 3000].into_iter().enumerate() {
        let mesh = random_mesh(&mut rng, count);
        let bvh = Bvh::build(&mesh);
        let mut hits = 0;
        for k in 0..2000 {
            let origin = rng.vec(2.5);
            let mut direction = (rng.vec(1.0) - origin * 0.3).normalize_or(Vec3::X);
            if k % 10 == 0 {
                // Axis-aligned rays have zero components (infinite inverse).
                direction = [Vec3::X, -Vec3::Y, Vec3::Z][k % 3];
            }
            let t_max = if k % 4 == 0 { 1.5 } else { f32::INFINITY };
            assert_agrees(&mesh, &bvh, origin, direction, t_max);
            hits += bvh.intersect(origin, direction, 0.0, t_max).is_some() as u32;
        }
        if count >= 40 {
            assert!(
                hits > 50,
                "round {round}: only {hits} hits; the test is not exercising hits"
            );
        }
    }
}

#[test]
fn generated_meshes_match_brute_force_on_a_grid() {
    let meshes = [
        Generator::Knot {
            p: 2,
            q: 3,
            segments: 96,
            sides: 12,
            tube_radius: 0.25,
        }
        .build(),
        Generator::Tree {
            seed: 3,
            depth: 3,
            leaves: 6,
        }
        .build(),
    ];
    for mesh in &meshes {
        let bvh = Bvh::build(mesh);
        let centre = mesh.bounds().center();
        for j in 0..40 {
            for i in 0..40 {
                let origin = centre + Vec3::new(i as f32 / 20.0 - 1.0, j as f32 / 20.0 - 1.0, 5.0);
                assert_agrees(mesh, &bvh, origin, -Vec3::Z, f32::INFINITY);
            }
        }
    }
}

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
