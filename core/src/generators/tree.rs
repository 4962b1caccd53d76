//! A branching tree: tapered cylinders for wood, small quads for leaves.

use std::f32::consts::TAU;

use glam::{Quat, Vec3};

use super::noise::SplitMix64;
use crate::mesh::{Material, Mesh};

const SIDES: usize = 6;
const BRANCHES: usize = 3;

struct Builder {
    rng: SplitMix64,
    wood: Mesh,
    leaves: Mesh,
    leaves_per_twig: u32,
}

impl Builder {
    fn cylinder(&mut self, from: Vec3, to: Vec3, r0: f32, r1: f32) {
        let axis = (to - from).normalize();
        let n1 = axis.any_orthonormal_vector();
        let n2 = axis.cross(n1);
        let base = self.wood.positions.len() as u32;
        let normals = self.wood.normals.get_or_insert_with(Vec::new);
        for (centre, radius) in [(from, r0), (to, r1)] {
            for k in 0..SIDES {
                let angle = k as f32 / SIDES as f32 * TAU;
                let radial = n1 * angle.cos() + n2 * angle.sin();
                self.wood.positions.push(centre + radial * radius);
                normals.push(radial);
            }
        }
        for k in 0..SIDES as u32 {
            let next = (k + 1) % SIDES as u32;
            let (a, b) = (base + k, base + next);
            let (c, d) = (base + SIDES as u32 + next, base + SIDES as u32 + k);
            self.wood.triangles.push([a, b, c]);
            self.wood.triangles.push([a, c, d]);
        }
    }

    fn leaf(&mut self, centre: Vec3) {
        let normal = Vec3::new(
            self.rng.range(-1.0, 1.0),
            self.rng.range(-0.2, 1.0),
            self.rng.range(-1.0, 1.0),
        )
        .normalize_or(Vec3::Y);
        let along = normal.any_orthonormal_vector();
        let across = normal.cross(along);
        let (length, width) = (self.rng.range(0.07, 0.12), self.rng.range(0.03, 0.05));
        let base = self.leaves.positions.len() as u32;
        for (s, t) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            self.leaves
                .positions
                .push(centre + along * (s * length) + across * (t * width));
        }
        self.leaves
            .normals
            .get_or_insert_with(Vec::new)
            .extend([normal; 4]);
        // along × across = normal, so this winding faces the stored normal.
        self.leaves.triangles.push([base, base + 1, base + 2]);
        self.leaves.triangles.push([base, base + 2, base + 3]);
    }

    fn branch(&mut self, from: Vec3, direction: Vec3, length: f32, radius: f32, depth: u32) {
        let to = from + direction * length;
        self.cylinder(from, to, radius, radius * 0.7);
        if depth == 0 {
            for _ in 0..self.leaves_per_twig {
                let offset = Vec3::new(
                    self.rng.range(-1.0, 1.0),
                    self.rng.range(-1.0, 1.0),
                    self.rng.range(-1.0, 1.0),
                ) * length
                    * 0.6;
                self.leaf(to + offset);
            }
            return;
        }
        let azimuth0 = self.rng.range(0.0, TAU);
        for k in 0..BRANCHES {
            let azimuth = azimuth0 + k as f32 * TAU / BRANCHES as f32;
            let tilt = self.rng.range(0.45, 0.8);
            let side = direction.any_orthonormal_vector();
            let axis = Quat::from_axis_angle(direction, azimuth) * side;
            let child = (Quat::from_axis_angle(axis, tilt) * direction).normalize();
            // Bias growth upwards a little, as trees do.
            let child = (child + Vec3::Y * 0.25).normalize();
            let scale = self.rng.range(0.62, 0.78);
            self.branch(to, child, length * scale, radius * 0.6, depth - 1);
        }
    }
}

/// The triangles [`tree`] makes: a cylinder per branch ([`BRANCHES`] children each,
/// `depth` levels below the trunk), two per leaf, `leaves_per_twig` on each twig.
pub(super) fn triangles(depth: u32, leaves_per_twig: u32) -> u64 {
    let branches = BRANCHES as u64;
    let twigs = branches.saturating_pow(depth);
    let all_branches = (0..=depth).map(|d| branches.saturating_pow(d)).sum::<u64>();
    all_branches * 2 * SIDES as u64 + twigs * 2 * u64::from(leaves_per_twig)
}

pub(super) fn tree(seed: u64, depth: u32, leaves_per_twig: u32) -> Mesh {
    let material = |name: &str, diffuse: Vec3| Material {
        name: name.into(),
        diffuse,
        diffuse_texture: None,
    };
    let empty = |m: Material| Mesh {
        normals: Some(Vec::new()),
        materials: vec![m],
        ..Default::default()
    };
    let mut builder = Builder {
        rng: SplitMix64::new(seed),
        wood: empty(material("bark", Vec3::new(0.36, 0.25, 0.16))),
        leaves: empty(material("leaf", Vec3::new(0.25, 0.55, 0.18))),
        leaves_per_twig,
    };
    builder.branch(Vec3::ZERO, Vec3::Y, 0.7, 0.08, depth);
    let mut mesh = builder.wood;
    if !builder.leaves.triangles.is_empty() {
        // (Two materials, and the vertices of at most `MAX_TREE_DEPTH` levels, tens of
        // millions: appending cannot fail.)
        mesh.append(builder.leaves)
            .expect("a tree's wood and leaves fit in one mesh");
    } else {
        mesh.materials.push(material("leaf", Vec3::new(0.25, 0.55, 0.18)));
    }
    mesh
}
