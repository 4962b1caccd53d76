//! The built-in `forest`: a wood of trees and rocks with knots and spheres among them —
//! a few hundred placements of four meshes, over 100 M triangles drawn as geometry
//! (the rocks' million each) — and a camera that orbits a knot in a clearing, then
//! flies low between the trees. Made by a seeded rule, so nothing is downloaded: the
//! same scene file every time ([`text`]), loaded like any other.

use std::fmt::Write;
use std::sync::LazyLock;

/// Half the side of the square the placements fill, metres.
const HALF_SIDE: f64 = 45.0;

/// How many of each mesh are placed: the rocks' count sets the triangles drawn as
/// geometry (100 × 1,002,252).
const TREES: usize = 150;
const ROCKS: usize = 100;
const KNOTS: usize = 20;
const SPHERES: usize = 24;

/// No placement's bounds come nearer the camera's path than this, metres: the eye never
/// passes through an object, nor so near that it is drawn as geometry.
const PATH_CLEARANCE: f64 = 1.5;

/// Two placements' centres lie at least this share of the sum of their reaches apart:
/// canopies may touch, trunks and rocks do not meet.
const SPACING: f64 = 0.7;

/// How far the knot reaches across the ground from its centre at scale 1, metres (half
/// its bounds' diagonal there, so whichever way it is turned); the other meshes' are
/// given where they are placed, in `make`.
const KNOT_REACH: f64 = 1.5;

/// The clearing's knot (`knot.1`), which the camera orbits first, as the default
/// scene's.
const ORBIT_CENTRE: [f64; 3] = [0.0, 1.3, 0.0];
const ORBIT_RADIUS: f64 = 4.5;

/// The low flight after the orbit, from where the orbit ends (eye height about 2 m).
const FLIGHT: [[f64; 3]; 7] = [
    [4.5, 2.1, 0.0],
    [12.0, 2.0, 6.0],
    [24.0, 1.8, -4.0],
    [34.0, 2.2, 10.0],
    [20.0, 2.0, 24.0],
    [0.0, 1.8, 30.0],
    [-20.0, 2.2, 22.0],
];

/// The forest's scene file.
pub(super) fn text() -> &'static str {
    static TEXT: LazyLock<String> = LazyLock::new(make);
    &TEXT
}

/// A small deterministic generator (xorshift64*): the same forest on every machine.
struct Rng(u64);

impl Rng {
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let unit = (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * unit
    }
}

/// Distance from `p` to the segment `a`–`b`, on the ground (x, z).
fn to_segment(p: [f64; 2], a: [f64; 3], b: [f64; 3]) -> f64 {
    let (ax, az, bx, bz) = (a[0], a[2], b[0], b[2]);
    let (dx, dz) = (bx - ax, bz - az);
    let t = (((p[0] - ax) * dx + (p[1] - az) * dz) / (dx * dx + dz * dz)).clamp(0.0, 1.0);
    ((p[0] - ax - t * dx).powi(2) + (p[1] - az - t * dz).powi(2)).sqrt()
}

/// Where the next placement, reaching `reach` metres from its centre across the
/// ground, may stand: within the square, clear of the orbit, the flight and every
/// placement so far (each with its reach).
fn free_spot(rng: &mut Rng, taken: &mut Vec<([f64; 2], f64)>, reach: f64) -> [f64; 2] {
    loop {
        let p = [rng.range(-HALF_SIDE, HALF_SIDE), rng.range(-HALF_SIDE, HALF_SIDE)];
        let from_orbit = (p[0] - ORBIT_CENTRE[0]).hypot(p[1] - ORBIT_CENTRE[2]);
        let clear_by = reach + PATH_CLEARANCE;
        let clear = from_orbit > ORBIT_RADIUS + clear_by
            && FLIGHT.windows(2).all(|w| to_segment(p, w[0], w[1]) > clear_by)
            && (taken.iter()).all(|(q, r)| (p[0] - q[0]).hypot(p[1] - q[1]) > SPACING * (reach + r));
        if clear {
            taken.push((p, reach));
            return p;
        }
    }
}

/// `first` and `count` more placements as a TOML `instances` list: each turned about
/// the vertical at random, scaled within `scales`, its origin `lift` × its scale above
/// the ground, clear of the others by `reach` × its scale.
fn instances(
    rng: &mut Rng,
    taken: &mut Vec<([f64; 2], f64)>,
    first: &str,
    count: usize,
    (scales, reach, lift): ((f64, f64), f64, f64),
) -> String {
    let mut list = format!("instances = [\n{first}");
    for _ in 0..count {
        let (yaw, scale) = (rng.range(0.0, 360.0), rng.range(scales.0, scales.1));
        let [x, z] = free_spot(rng, taken, reach * scale);
        let _ = writeln!(
            list,
            "  {{ translate = [{x:.2}, {:.3}, {z:.2}], rotate_deg = [0, {yaw:.1}, 0], scale = {scale:.3} }},",
            lift * scale
        );
    }
    list + "]\n"
}

fn make() -> String {
    let mut rng = Rng(0x5EED_F0E5_7000_0001);
    // The clearing's knot stands at the orbit's centre.
    let mut taken = vec![([ORBIT_CENTRE[0], ORBIT_CENTRE[2]], KNOT_REACH)];
    let [cx, cy, cz] = ORBIT_CENTRE;
    let flight = FLIGHT
        .map(|[x, y, z]| format!("[{x:.1}, {y:.1}, {z:.1}]"))
        .join(", ");
    let mut text = format!(
        r#"# The built-in forest (core/src/scene/forest.rs makes this text).
name = "forest"
background = [0.62, 0.74, 0.88]
ambient = [0.18, 0.18, 0.2]

[camera]
fov_deg = 60

[[camera.path]]
kind = "orbit"
center = [{cx:.1}, {cy:.1}, {cz:.1}]
radius = {ORBIT_RADIUS:.1}
height = 0.8
turns = 1.0
frames = 240

[[camera.path]]
kind = "fly"
points = [{flight}]
frames = 300

[[lights]]
kind = "directional"
direction = [-0.4, -1.0, -0.3]
color = [1.0, 0.97, 0.9]
intensity = 0.85

[[lights]]
kind = "directional"
direction = [0.6, -0.2, 0.7]
color = [0.8, 0.9, 1.0]
intensity = 0.25

[[objects]]
name = "ground"
generator = {{ kind = "plane", size = {size:.1}, divisions = 1 }}
diffuse = [0.45, 0.5, 0.4]
specular = 0.0
"#,
        size = 2.0 * HALF_SIDE + 20.0,
    );
    let objects = [
        (
            "tree",
            r#"generator = { kind = "tree", seed = 7, depth = 5, leaves = 10 }"#,
            "specular = 0.05",
            TREES,
            ((1.5, 2.5), 1.6, 0.0),
        ),
        (
            "rock",
            r#"generator = { kind = "rock", resolution = 289, seed = 11 }"#,
            "specular = 0.1\nshininess = 16",
            ROCKS,
            ((0.5, 1.2), 1.5, 1.0),
        ),
        (
            "knot",
            r#"generator = { kind = "knot", p = 2, q = 3, segments = 720, sides = 32, tube_radius = 0.28 }
scale = 1.2
diffuse = [0.85, 0.7, 0.2]"#,
            "specular = 0.4\nshininess = 64",
            KNOTS,
            ((0.6, 1.0), KNOT_REACH, 1.3),
        ),
        (
            "sphere",
            r#"generator = { kind = "sphere", subdivisions = 5 }
diffuse = [0.8, 0.25, 0.2]"#,
            "specular = 0.5\nshininess = 48",
            SPHERES,
            ((0.5, 1.0), 1.45, 1.0),
        ),
    ];
    for (name, mesh, material, count, shape) in objects {
        // The knot orbited first, `knot.1`, stands in the clearing.
        let first = match name {
            "knot" => format!("  {{ translate = [{cx:.1}, {cy:.1}, {cz:.1}] }},\n"),
            _ => String::new(),
        };
        let list = instances(&mut rng, &mut taken, &first, count, shape);
        let _ = write!(
            text,
            "\n[[objects]]\nname = \"{name}\"\n{mesh}\n{material}\n{list}"
        );
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Scene;

    /// The forest loads: every placement an object, clear of the camera's path, over
    /// 100 M triangles drawn (four meshes and the ground in memory).
    #[test]
    fn the_forest_is_large_and_clear_of_its_path() {
        let scene = Scene::load("forest").expect("forest");
        let placements = TREES + ROCKS + 1 + KNOTS + SPHERES;
        assert_eq!(scene.objects.len(), 1 + placements);
        let drawn: usize = scene.objects.iter().map(|o| o.mesh.triangle_count()).sum();
        assert!(drawn >= 100_000_000, "{drawn} triangles");
        let mut meshes: Vec<*const crate::mesh::Mesh> = scene
            .objects
            .iter()
            .map(|o| std::sync::Arc::as_ptr(&o.mesh))
            .collect();
        meshes.sort();
        meshes.dedup();
        assert_eq!(meshes.len(), 5, "ground, tree, rock, knot, sphere");
        for frame in 0..scene.path.frame_count() {
            let eye = scene.path.pose(frame).expect("pose").eye;
            for o in &scene.objects[1..] {
                assert!(
                    !o.world_bounds().contains(eye.as_vec3()),
                    "frame {frame}: the eye in {}",
                    o.name
                );
            }
        }
    }
}
