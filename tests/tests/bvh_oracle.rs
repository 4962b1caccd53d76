//! The tracer's BVH against the independent oracle (`relief_tests::oracle`: every
//! triangle, f64, signed volumes): the same nearest hit — distance, triangle and
//! barycentrics — for rays through random meshes (degenerate and edge-sharing
//! triangles among them) and generated ones. Where two triangles tie
//! (a shared edge, a coplanar overlap), the one the BVH names must itself be crossed
//! there, at the barycentrics it reports. A bake's beams of parallel rays are held to
//! the same, and must leave no hole in a surface whose edges run through texel centres.

use glam::Vec3;

use relief_core::generators::Generator;
use relief_core::mesh::{Material, Mesh};
use relief_tests::oracle::{nearest_hit, ray_triangle};
use relief_trace::bvh::{Bvh, Hit, PlaneRays};
use relief_trace::tiles::Block;

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
    check_hit(
        mesh,
        bvh.intersect(origin, direction, 0.0, t_max),
        origin,
        direction,
        t_max,
        tally,
    );
}

/// [`check`] for a hit found otherwise (a beam's).
fn check_hit(mesh: &Mesh, got: Option<Hit>, origin: Vec3, direction: Vec3, t_max: f32, tally: &mut Tally) {
    tally.rays += 1;
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

/// The knot the tests trace: a tube of 96 × 12 segments.
fn test_knot() -> Mesh {
    Generator::Knot {
        p: 2,
        q: 3,
        segments: 96,
        sides: 12,
        tube_radius: 0.25,
    }
    .build()
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
        (test_knot(), 10),
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

/// An orthographic texture's frame looking at `mesh` along `f`: texels of `texel`
/// world units, `size` a side, centred on the mesh; the plane two radii before it.
fn parallel_frame(mesh: &Mesh, f: Vec3, texel: f32, size: u32) -> (Vec3, Vec3, Vec3, Vec3) {
    let f = f.normalize();
    let up = if f.y.abs() < 0.9 { Vec3::Y } else { Vec3::Z };
    let a = f.cross(up).normalize() * texel;
    let b = f.cross(a).normalize() * texel;
    let radius = mesh.bounds().extent().length();
    let centre = mesh.bounds().center() - f * 2.0 * radius;
    let origin = centre - (a + b) * (size as f32 * 0.5);
    (origin, a, b, f)
}

/// Every texel of a `size²` texture traced in beams of [`Block::tiles`], parallel or from a
/// centre set back from the plane by three of the mesh's radii, then each checked
/// against the oracle as its own ray.
fn check_beams(
    mesh: &Mesh,
    bvh: &Bvh,
    (origin, a, b, f): (Vec3, Vec3, Vec3, Vec3),
    size: u32,
    perspective: bool,
    tally: &mut Tally,
) {
    let radius = mesh.bounds().extent().length();
    let t_max = 4.0 * radius;
    let middle = origin + (a + b) * (size as f32 * 0.5);
    let centre = middle - f * 3.0 * radius;
    let rays = match perspective {
        false => PlaneRays::parallel(origin, a, b, f, 0.0, t_max),
        true => PlaneRays::from_centre(centre, origin, a, b, f, 0.0, t_max),
    }
    .expect("a frame spanning space");
    let mut hits = Vec::new();
    let texture = Block {
        x0: 0,
        y0: 0,
        width: size,
        height: size,
    };
    for block in texture.tiles() {
        hits.clear();
        hits.resize((block.width * block.height) as usize, None);
        bvh.intersect_block(&rays, block, &mut hits);
        for ((i, j), &hit) in block.pixels().zip(&hits) {
            let start = origin + a * (i as f32 + 0.5) + b * (j as f32 + 0.5);
            // (From the centre: scaled to 1 along `f`, so `t` is the displacement.)
            let direction = if perspective {
                (start - centre) / (3.0 * radius)
            } else {
                f
            };
            check_hit(mesh, hit, start, direction, t_max, tally);
        }
    }
}

/// Beams of a bake's rays, parallel and from a centre, through random meshes, from
/// several directions (axis-aligned among them), at texels from a tenth of a triangle
/// to several.
#[test]
fn beams_match_the_oracle() {
    let mut rng = Rng(0xD1B5_4A32_D192_ED03);
    for count in [1usize, 3, 40, 300, 3000] {
        let mesh = random_mesh(&mut rng, count);
        let bvh = Bvh::build(&mesh);
        let mut tally = Tally::default();
        for (k, f) in [Vec3::Z, -Vec3::X, Vec3::new(0.3, -0.5, 0.8), rng.vec(1.0)]
            .into_iter()
            .enumerate()
        {
            let texel = [0.004, 0.03, 0.05, 0.2][k];
            for perspective in [false, true] {
                check_beams(
                    &mesh,
                    &bvh,
                    parallel_frame(&mesh, f, texel, 61),
                    61,
                    perspective,
                    &mut tally,
                );
            }
        }
        eprintln!("{count} triangles, beams: {tally:?}");
        if count >= 40 {
            assert!(
                tally.hits > tally.rays / 10,
                "{count} triangles: too few hits to test: {tally:?}"
            );
        }
        assert!(tally.grazing <= tally.rays / 1000, "{count} triangles: {tally:?}");
    }
    for mesh in [test_knot(), Generator::Sphere { subdivisions: 3 }.build()] {
        let bvh = Bvh::build(&mesh);
        let mut tally = Tally::default();
        let texel = mesh.bounds().extent().length() / 64.0;
        let frame = parallel_frame(&mesh, Vec3::new(0.45, 0.35, 0.82), texel, 64);
        for perspective in [false, true] {
            check_beams(&mesh, &bvh, frame, 64, perspective, &mut tally);
        }
        eprintln!("generated, beams: {tally:?}");
        assert!(tally.hits > tally.rays / 8, "too few hits to test: {tally:?}");
        assert!(tally.grazing <= tally.rays / 1000, "{tally:?}");
    }
}

/// A fan of long triangles round a texel centre of a texture 4,096 texels wide, in a
/// turned frame: each spoke runs through hundreds of texel centres, up to rounding, and
/// is shared by the two triangles either side of it. Beams must hit every texel centre
/// on a spoke, however rounding falls: edges evaluated from either end would leave holes.
#[test]
fn beams_leave_no_hole_along_shared_edges() {
    const SIZE: u32 = 4096;
    let hub = glam::DVec2::splat(SIZE as f64 / 2.0 + 0.5);
    // Spoke directions in texels, in angle order; each reaches 2,000 texels or so.
    let mut steps: Vec<glam::IVec2> = (-5..=5)
        .flat_map(|x| (-5..=5).map(move |y| glam::IVec2::new(x, y)))
        .filter(|s| *s != glam::IVec2::ZERO && gcd(s.x.unsigned_abs(), s.y.unsigned_abs()) == 1)
        .collect();
    steps.sort_by(|p, q| {
        (p.y as f64)
            .atan2(p.x as f64)
            .total_cmp(&(q.y as f64).atan2(q.x as f64))
    });
    let reach = |s: glam::IVec2| (2000.0 / s.as_dvec2().length()).floor();
    // Texels a tenth of a unit, turned 30° about the view axis, far from the world's
    // origin: no projection is exact.
    let (sin, cos) = 30f64.to_radians().sin_cos();
    let (a, b) = (
        glam::DVec3::new(cos, sin, 0.0) * 0.1,
        glam::DVec3::new(-sin, cos, 0.0) * 0.1,
    );
    let origin = glam::DVec3::new(37.0, -21.0, 5.0);
    let world =
        |p: glam::DVec2, height: f64| (origin + a * p.x + b * p.y + glam::DVec3::Z * height).as_vec3();
    // Corners a ten-thousandth of a texel off their places: a texel centre on a spoke
    // is then as near its edge as rounding can tell.
    let mut rng = Rng(0x5851_F42D_4C95_7F2D);
    let mut jitter = || glam::DVec2::new(rng.next() as f64 - 0.5, rng.next() as f64 - 0.5) * 2e-4;
    let mut mesh = Mesh {
        positions: vec![world(hub + jitter(), 1.0)],
        materials: vec![Material::default()],
        ..Default::default()
    };
    for (k, &s) in steps.iter().enumerate() {
        mesh.positions.push(world(
            hub + s.as_dvec2() * reach(s) + jitter(),
            1.0 + 0.1 * (k % 3) as f64,
        ));
    }
    let spokes = steps.len() as u32;
    mesh.triangles = (1..=spokes).map(|k| [0, k, k % spokes + 1]).collect();
    let bvh = Bvh::build(&mesh);
    let rays = PlaneRays::parallel(origin.as_vec3(), a.as_vec3(), b.as_vec3(), Vec3::Z, 0.0, 10.0)
        .expect("the axes span space");
    let mut on_spokes = 0;
    let mut holes = Vec::new();
    let mut hits = Vec::new();
    for &s in &steps {
        for m in 1..reach(s) as i32 {
            let centre = hub + (s * m).as_dvec2();
            let (i, j) = ((centre.x - 0.5) as u32, (centre.y - 0.5) as u32);
            let block = Block {
                x0: i,
                y0: j,
                width: 1,
                height: 1,
            };
            hits.clear();
            hits.push(None);
            bvh.intersect_block(&rays, block, &mut hits);
            on_spokes += 1;
            if hits[0].is_none() {
                holes.push((i, j));
            }
        }
    }
    assert!(on_spokes > 10_000, "{on_spokes} texel centres on spokes");
    assert!(
        holes.is_empty(),
        "{} of {on_spokes} texel centres on shared edges missed: {:?}",
        holes.len(),
        &holes[..holes.len().min(10)]
    );
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}
