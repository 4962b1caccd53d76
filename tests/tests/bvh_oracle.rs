//! The tracer's BVH against the independent oracle (`relief_tests::oracle`: every
//! triangle, f64, signed volumes): the same nearest hit — distance, triangle and
//! barycentrics — for rays through random and generated meshes. Where two triangles tie
//! (a shared edge, a coplanar overlap), the one the BVH names must itself be crossed
//! there, at the barycentrics it reports.

use glam::Vec3;

use relief_core::generators::Generator;
use relief_core::mesh::{Material, Mesh};
use relief_tests::oracle::{nearest_hit, ray_triangle};
use relief_trace::bvh::Bvh;

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32) / (1u64 << 24) as f32
    }

    fn vec(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.next() - 0.5, self.next() - 0.5, self.next() - 0.5) * scale
    }
}

/// Rays that agree, and rays that graze an edge so closely (within `1e-5` of the
/// triangle's border in barycentrics) that f32 and f64 may answer differently.
#[derive(Debug, Default)]
struct Tally {
    rays: usize,
    hits: usize,
    grazing: usize,
}

fn check(mesh: &Mesh, bvh: &Bvh, origin: Vec3, direction: Vec3, tally: &mut Tally) {
    tally.rays += 1;
    let got = bvh.intersect(origin, direction, 0.0, f32::INFINITY);
    let want = nearest_hit(mesh, origin, direction);
    let near_border = |u: f64, v: f64| u.min(v).min(1.0 - u - v) < 1e-5;
    match (got, want) {
        (None, None) => {}
        (Some(g), Some(w)) => {
            tally.hits += 1;
            let tolerance = 1e-4 * w.t.max(1e-3);
            assert!(
                (g.t as f64 - w.t).abs() <= tolerance,
                "t {} vs {} for {origin} {direction}",
                g.t,
                w.t
            );
            // The triangle the BVH names, crossed there at the barycentrics it says.
            let (t, u, v) = ray_triangle(origin, direction, mesh.corners(g.triangle as usize))
                .unwrap_or_else(|| {
                    panic!(
                        "the BVH's triangle {} is not crossed by {origin} {direction}",
                        g.triangle
                    )
                });
            assert!((t - w.t).abs() <= tolerance, "tie at {t} vs {}", w.t);
            assert!(
                (g.u as f64 - u).abs() < 1e-3 && (g.v as f64 - v).abs() < 1e-3,
                "barycentrics ({}, {}) vs ({u}, {v}) on triangle {}",
                g.u,
                g.v,
                g.triangle
            );
        }
        (None, Some(w)) if near_border(w.u, w.v) => tally.grazing += 1,
        (Some(g), None) if near_border(g.u as f64, g.v as f64) => tally.grazing += 1,
        _ => panic!("hit/miss differ: BVH {got:?}, oracle {want:?}, ray {origin} {direction}"),
    }
}

fn random_mesh(rng: &mut Rng, count: usize) -> Mesh {
    let mut positions = Vec::new();
    let mut triangles = Vec::new();
    for k in 0..count {
        let centre = rng.vec(8.0);
        for _ in 0..3 {
            positions.push(centre + rng.vec(1.5));
        }
        let i = 3 * k as u32;
        triangles.push([i, i + 1, i + 2]);
    }
    Mesh {
        positions,
        triangles,
        materials: vec![Material::default()],
        ..Default::default()
    }
}

#[test]
fn the_bvh_finds_what_the_independent_oracle_finds() {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    let meshes = [
        random_mesh(&mut rng, 300),
        Generator::Knot {
            p: 2,
            q: 3,
            segments: 96,
            sides: 12,
            tube_radius: 0.25,
        }
        .build(),
        Generator::Sphere { subdivisions: 3 }.build(),
    ];
    for mesh in &meshes {
        let bvh = Bvh::build(mesh);
        let centre = mesh.bounds().center();
        let radius = mesh.bounds().extent().length();
        let mut tally = Tally::default();
        // A grid of parallel rays (a bake's), then rays from random points towards
        // random points near the mesh (a reference's).
        for j in 0..48 {
            for i in 0..48 {
                let offset = Vec3::new(i as f32 / 24.0 - 1.0, j as f32 / 24.0 - 1.0, 0.0) * radius * 0.6;
                check(
                    mesh,
                    &bvh,
                    centre + offset + Vec3::Z * radius * 2.0,
                    -Vec3::Z,
                    &mut tally,
                );
            }
        }
        for _ in 0..2000 {
            let origin = centre + rng.vec(4.0 * radius);
            let towards = centre + rng.vec(radius);
            check(mesh, &bvh, origin, towards - origin, &mut tally);
        }
        eprintln!("{tally:?}");
        assert!(tally.hits > tally.rays / 10, "too few hits to test: {tally:?}");
        assert!(tally.grazing <= tally.rays / 1000, "{tally:?}");
    }
}
