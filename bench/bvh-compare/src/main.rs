//! Relief's BVH against `obvhs` (CWBVH, the fastest CPU traversal it offers) on the
//! default scene's heavy object, with the exact rays of a 256² bake. Prints build times,
//! single-thread traversal throughput, and their ratios, measured in the same run.
//!
//! `cargo run --release --manifest-path bench/bvh-compare/Cargo.toml [-- OBJECT [SIZE]]`

use std::time::{Duration, Instant};

use glam::Vec3;
use obvhs::{BvhBuildParams, cwbvh::builder::build_cwbvh_from_tris, ray::RayHit, triangle::Triangle};
use relief_core::relief::SourceCamera;
use relief_core::scene::Scene;
use relief_trace::bvh::{Bvh, Hit, Ray};

fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = f();
    for _ in 0..runs {
        let start = Instant::now();
        out = f();
        best = best.min(start.elapsed().as_secs_f64() * 1e3);
    }
    (best, out)
}

fn a3(v: Vec3) -> glam_obvhs::Vec3A {
    glam_obvhs::Vec3A::from_array(v.to_array())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let object_name = std::env::args().nth(1).unwrap_or_else(|| "rock".into());
    let size: u32 = std::env::args().nth(2).map_or(Ok(256), |s| s.parse())?;
    let scene = Scene::load("default")?;
    let object = scene.object(&object_name)?;
    let mesh = &object.mesh;
    let radius = object.bounds.extent().length() * 0.5;
    let eye = object.bounds.center() + Vec3::new(0.45, 0.35, 0.82).normalize() * radius * 3.0;
    let camera = SourceCamera::facing(eye, &object.bounds, size, size)?;
    let span = camera.depth_far - camera.depth_near;
    let rays: Vec<Ray> = (0..size)
        .flat_map(|j| (0..size).map(move |i| (i, j)))
        .map(|(i, j)| Ray {
            origin: camera.texel_origin(i, j),
            direction: camera.f,
            t_min: -span * 1e-4,
            t_max: span * 1.0001,
        })
        .collect();

    // Relief.
    let (ours_build_ms, ours) = best_of(3, || Bvh::build(mesh));
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let (ours_trace_ms, ours_hits) = one.install(|| {
        best_of(5, || {
            let mut hits = vec![None; rays.len()];
            for (chunk, out) in rays.chunks(64).zip(hits.chunks_mut(64)) {
                ours.intersect_batch(chunk, out);
            }
            hits
        })
    });

    // obvhs: triangles reordered into leaf order, as its own examples do.
    let tris: Vec<Triangle> = (0..mesh.triangle_count())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            Triangle {
                v0: a3(a),
                v1: a3(b),
                v2: a3(c),
            }
        })
        .collect();
    let (theirs_build_ms, cwbvh) =
        best_of(3, || build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default()));
    let ordered: Vec<Triangle> = cwbvh.primitive_indices.iter().map(|&i| tris[i as usize]).collect();
    let (theirs_trace_ms, theirs_hits) = best_of(5, || {
        rays.iter()
            .map(|r| {
                let ray = obvhs::ray::Ray::new(a3(r.origin), a3(r.direction), r.t_min, r.t_max);
                let mut hit = RayHit::none();
                cwbvh
                    .ray_traverse(ray, &mut hit, |ray, id| ordered[id].intersect(ray))
                    .then_some(hit.t)
            })
            .collect::<Vec<_>>()
    });

    let disagree = ours_hits
        .iter()
        .zip(&theirs_hits)
        .filter(|(a, b): &(&Option<Hit>, &Option<f32>)| match (a, b) {
            (None, None) => false,
            (Some(a), Some(t)) => (a.t - t).abs() > 1e-4 * span,
            _ => true,
        })
        .count();
    let mrays = |ms: f64| rays.len() as f64 / (ms * 1e-3) / 1e6;
    println!("{object_name}: {} triangles, {size}² orthographic rays, one thread", mesh.triangle_count());
    println!(
        "build   relief {ours_build_ms:8.1} ms   obvhs cwbvh (medium) {theirs_build_ms:8.1} ms   time relief/obvhs {:.2}",
        ours_build_ms / theirs_build_ms
    );
    println!(
        "trace   relief {:8.2} Mrays/s  obvhs cwbvh {:8.2} Mrays/s   time relief/obvhs {:.2}",
        mrays(ours_trace_ms),
        mrays(theirs_trace_ms),
        ours_trace_ms / theirs_trace_ms
    );
    println!("rays whose hit differs: {disagree} of {}", rays.len());
    Ok(())
}
