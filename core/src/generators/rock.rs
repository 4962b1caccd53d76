//! A rugged rock: a cube-sphere displaced by fractal noise. The heavy object of the
//! default scene (a million triangles at resolution 289).

use std::f32::consts::FRAC_PI_4;

use glam::Vec3;

use super::noise::fbm;
use crate::mesh::{Material, Mesh};

const AMPLITUDE: f32 = 0.35;
const FREQUENCY: f32 = 2.2;
const OCTAVES: u32 = 7;

/// The rock's surface point in direction `dir` (unit).
fn surface(dir: Vec3, seed: u64) -> Vec3 {
    let ridged = 1.0 - fbm(dir * FREQUENCY, seed, OCTAVES).abs() * 2.0;
    dir * (1.0 + AMPLITUDE * (ridged * 0.5 - 0.25))
}

/// Outward normal by central differences of the surface around `dir`; it depends on the
/// direction only, so vertices duplicated along cube seams get identical normals.
fn surface_normal(dir: Vec3, seed: u64, step: f32) -> Vec3 {
    let t1 = dir.any_orthonormal_vector();
    let t2 = dir.cross(t1);
    let at = |d: Vec3| surface(d.normalize(), seed);
    let du = at(dir + t1 * step) - at(dir - t1 * step);
    let dv = at(dir + t2 * step) - at(dir - t2 * step);
    let n = du.cross(dv).normalize_or_zero();
    if n == Vec3::ZERO { dir } else { n }
}

pub(super) fn rock(resolution: u32, seed: u64) -> Mesh {
    use rayon::prelude::*;
    let n = resolution as usize;
    // (face normal, u axis, v axis) with u × v = normal, so the winding faces outwards.
    let faces = [
        (Vec3::X, -Vec3::Z, Vec3::Y),
        (-Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, -Vec3::Z),
        (-Vec3::Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (-Vec3::Z, -Vec3::X, Vec3::Y),
    ];
    // Equal-angle warp of the cube grid, computed once so shared seam points come out
    // bit-identical on both faces.
    let warp: Vec<f32> = (0..=n)
        .map(|i| (FRAC_PI_4 * (2.0 * i as f32 / n as f32 - 1.0)).tan())
        .collect();
    let step = 0.7 / n as f32;
    let per_face = (n + 1) * (n + 1);
    let vertices: Vec<(Vec3, Vec3)> = (0..6 * per_face)
        .into_par_iter()
        .map(|k| {
            let (face, rest) = (k / per_face, k % per_face);
            let (normal, u, v) = faces[face];
            let (i, j) = (rest % (n + 1), rest / (n + 1));
            let dir = (normal + u * warp[i] + v * warp[j]).normalize();
            (surface(dir, seed), surface_normal(dir, seed, step))
        })
        .collect();
    let (positions, normals) = vertices.into_iter().unzip();
    let mut triangles = Vec::with_capacity(12 * n * n);
    for face in 0..6 {
        let index = |i: usize, j: usize| (face * per_face + j * (n + 1) + i) as u32;
        for j in 0..n {
            for i in 0..n {
                triangles.push([index(i, j), index(i + 1, j), index(i + 1, j + 1)]);
                triangles.push([index(i, j), index(i + 1, j + 1), index(i, j + 1)]);
            }
        }
    }
    Mesh {
        positions,
        normals: Some(normals),
        triangles,
        materials: vec![Material {
            name: "rock".into(),
            diffuse: Vec3::new(0.55, 0.5, 0.45),
            diffuse_texture: None,
        }],
        ..Default::default()
    }
}
