//! The tracer's BVH against the independent oracle (`relief_tests::oracle`: every
//! triangle, f64, signed volumes): the same nearest hit — distance, triangle and
//! barycentrics — for rays through random meshes (degenerate and edge-sharing
//! triangles among them) and generated ones. Where two triangles tie
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

    /// A point in the cube `[-scale, scale]³`.
    fn vec(&mut self, scale: f32) -> Vec3 {
        Vec3::new(self.next(), self.next(), self.next()) * 2.0 * scale - Vec3::splat(scale)
    }
}

/// Rays tested, rays that hit, and rays that graze an edge (or the end of the ray) so
/// closely that f32 and f64 may answer differently: within `1e-5` of the triangle's
/// border in barycentrics, or of `t_max`.
#[derive(Debug, Default)]
struct Tally {
    rays: usize,
    hits: usize,
    grazing: usize,
}

fn check(mesh: &Mesh, bvh: &Bvh, origin: Vec3, direction: Vec3, t_max: f32, tally: &mut Tally) {
    tally.rays += 1;
    let got = bvh.intersect(origin, direction, 0.0, t_max);
    let nearest = nearest_hit(mesh, origin, direction);
    let want = nearest.filter(|h| h.t < t_max as f64);
    let grazes = |u: f64, v: f64, t: f64| {
        u.min(v).min(1.0 - u - v) < 1e-5 || (t - t_max as f64).abs() < 1e-5 * t.max(1.0)
    };
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
        (None, Some(w)) if grazes(w.u, w.v, w.t) => tally.grazing += 1,
        (Some(g), None) if grazes(g.u as f64, g.v as f64, g.t as f64) => tally.grazing += 1,
        _ => {
            panic!("hit/miss differ: BVH {got:?}, oracle {nearest:?}, ray {origin} {direction} up to {t_max}")
        }
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

/// Random meshes of 1 to 3,000 triangles, rays from anywhere (some axis-aligned, whose
/// inverse direction is infinite; some ending at `t_max` 1.5).
#[test]
fn random_meshes_match_the_oracle() {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for count in [1usize, 2, 3, 9, 40, 300, 3000] {
        let mesh = random_mesh(&mut rng, count);
        let bvh = Bvh::build(&mesh);
        let mut tally = Tally::default();
        for k in 0..2000 {
            let origin = rng.vec(2.5);
            let mut direction = (rng.vec(1.0) - origin * 0.3).normalize_or(Vec3::X);
            if k % 10 == 0 {
                direction = [Vec3::X, -Vec3::Y, Vec3::Z][k % 3];
            }
            let t_max = if k % 4 == 0 { 1.5 } else { f32::INFINITY };
            check(&mesh, &bvh, origin, direction, t_max, &mut tally);
        }
        eprintln!("{count} triangles: {tally:?}");
        if count >= 40 {
            assert!(
                tally.hits > 50,
                "{count} triangles: too few hits to test: {tally:?}"
            );
        }
        assert!(tally.grazing <= tally.rays / 1000, "{count} triangles: {tally:?}");
    }
}

/// Generated meshes (a knot, a tree, a sphere): a grid of parallel rays (a bake's), then
/// rays from random points towards random points near the mesh (a reference's).
#[test]
fn generated_meshes_match_the_oracle() {
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    // Each with the share of rays that must hit for the test to mean something (the
    // tree's leaves are sparse).
    let meshes = [
        (
            Generator::Knot {
                p: 2,
                q: 3,
                segments: 96,
                sides: 12,
                tube_radius: 0.25,
            }
            .build(),
            10,
        ),
        (
            Generator::Tree {
                seed: 3,
                depth: 3,
                leaves: 6,
            }
            .build(),
            20,
        ),
        (Generator::Sphere { subdivisions: 3 }.build(), 10),
    ];
    for (mesh, hit_share) in &meshes {
        let bvh = Bvh::build(mesh);
        let centre = mesh.bounds().center();
        let radius = mesh.bounds().extent().length();
        let mut tally = Tally::default();
        for j in 0..48 {
            for i in 0..48 {
                let offset = Vec3::new(i as f32 / 24.0 - 1.0, j as f32 / 24.0 - 1.0, 0.0) * radius * 0.6;
                let origin = centre + offset + Vec3::Z * radius * 2.0;
                check(mesh, &bvh, origin, -Vec3::Z, f32::INFINITY, &mut tally);
            }
        }
        for _ in 0..2000 {
            let origin = centre + rng.vec(2.0 * radius);
            let towards = centre + rng.vec(0.5 * radius);
            check(mesh, &bvh, origin, towards - origin, f32::INFINITY, &mut tally);
        }
        eprintln!("{tally:?}");
        assert!(
            tally.hits > tally.rays / hit_share,
            "too few hits to test: {tally:?}"
        );
        assert!(tally.grazing <= tally.rays / 1000, "{tally:?}");
    }
}
