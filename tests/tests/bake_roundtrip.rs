//! `relief bake` checked by an independent ray caster (`relief_tests::oracle`: every
//! triangle, in f64, by signed volumes — no code shared with the tracer), reading only
//! `texture.json` and the PNG planes the command wrote: each texel's centre ray, and
//! on the outline its rim rays, whose deepest hit on the texel's own surface gives its
//! depth.

use std::path::Path;

use glam::Vec3;

use relief_core::joins::{join_reach, slope_along};
use relief_core::relief::{ReliefTexture, decode_normal_rgb8};
use relief_core::scene::Scene;
use relief_tests::oracle::nearest_hit;
use relief_tests::{relief, scratch, shared_models};
use relief_trace::rim::{RIM_MAX_TURN_DEG, RIM_RAY_OFFSETS};

/// Agreement between a baked texture and brute-force rays through its texel centres.
#[derive(Debug, Default)]
struct Agreement {
    texels: usize,
    covered: usize,
    mask_mismatch: usize,
    depth_mismatch: usize,
    normal_mismatch: usize,
    /// Rim texels whose depth is a rim ray's, deeper than their centre's.
    rim_deepened: usize,
}

fn check(scene_spec: &str, object: &str, eye: &str, size: u32, bits: u32) -> Agreement {
    check_in(scene_spec, object, eye, size, bits, "orthographic")
}

/// [`check`] for `--projection projection`: a perspective texture's rays start at its
/// eye.
fn check_in(scene_spec: &str, object: &str, eye: &str, size: u32, bits: u32, projection: &str) -> Agreement {
    let dir = scratch(&format!("bake-{object}-{bits}-{projection}"));
    let out = relief(&[
        "bake",
        "--scene",
        scene_spec,
        "--object",
        object,
        "--eye",
        eye,
        "--size",
        &size.to_string(),
        "--depth-bits",
        &bits.to_string(),
        "--projection",
        projection,
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "bake failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let texture = ReliefTexture::read_dir(&dir).expect("reading the baked texture");
    let scene = Scene::load(scene_spec).unwrap();
    let mesh = &scene.object(object).unwrap().mesh;
    let c = texture.camera;
    assert_eq!((c.width, c.height), (size, size));
    assert!(c.f.dot(c.a.cross(c.b).normalize()) > 0.9999, "f = a×b/|a×b|");
    // (`--eye` is in the world; the texture in the object's own frame.)
    let target = scene.object(object).unwrap();
    let eye_v = target.to_local(relief_core::vector::parse_dvec3(eye).unwrap());
    assert!(c.f.dot((target.local_bounds.center() - eye_v).normalize()) > 0.9999);
    assert_eq!(
        c.centre,
        (projection == "perspective").then_some(eye_v),
        "{projection}"
    );
    let quantum = c.depth_quantum(texture.depth_bits);
    let stored_covered = |i: i64, j: i64| {
        (0..size as i64).contains(&i)
            && (0..size as i64).contains(&j)
            && texture.world_point(i as u32, j as u32).is_some()
    };
    // The nearest surface on the ray through plane point `(u, v)`, from depth `from` on
    // when given: its depth along `f`, and its shading normal. Cast from far in front of
    // the plane (the caster knows nothing of bounds), or from the eye.
    let cast = |u: f32, v: f32, from: Option<f32>| {
        let plane_point = c.point(u, v, 0.0);
        let (start, direction) = match (from, c.centre) {
            (Some(t), _) => (c.point(u, v, t), c.point(u, v, t + 1.0) - c.point(u, v, t)),
            (None, None) => (plane_point - c.f * (c.depth_far * 4.0 + 1.0), c.f),
            (None, Some(centre)) => (centre, plane_point - centre),
        };
        let hit = nearest_hit(mesh, start, direction)?;
        let surface = start.as_dvec3() + direction.as_dvec3() * hit.t;
        let depth = (surface - plane_point.as_dvec3()).dot(c.f.as_dvec3()) as f32;
        Some((
            depth,
            mesh.shading_normal(hit.triangle, hit.u as f32, hit.v as f32),
        ))
    };
    let mut agreement = Agreement::default();
    for j in 0..size {
        for i in 0..size {
            agreement.texels += 1;
            let (u, v) = (i as f32 + 0.5, j as f32 + 0.5);
            match (cast(u, v, None), texture.world_point(i, j)) {
                (None, None) => {}
                (Some((centre_depth, normal)), Some(point)) => {
                    agreement.covered += 1;
                    let got = decode_normal_rgb8(texture.normal[texture.index(i, j)]);
                    if got.angle_between(normal) > 2f32.to_radians() {
                        agreement.normal_mismatch += 1;
                    }
                    // A rim texel takes the deepest of its rim rays' hits joined to it
                    // (`relief_core::joins`, from its stored normal), each the nearest
                    // from a quantum short of its depth on, one side at a time
                    // (`relief_trace::rim`, restated here). Its depth is the bake's, as
                    // stored before: the centre hit's, rounded to its level.
                    let bits = texture.depth_bits;
                    let rounded = c.depth_of_level(c.level_of_depth(centre_depth, bits), bits);
                    let mut want = centre_depth;
                    for (di, dj) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                        if stored_covered(i as i64 + di, j as i64 + dj) {
                            continue;
                        }
                        let across = if di != 0 { c.a } else { c.b };
                        let slope = slope_along(got, across.normalize(), c.f);
                        // (Offsets in turn, until one finds the texel's surface.)
                        for offset in RIM_RAY_OFFSETS {
                            let from = Some(rounded - quantum);
                            let own = cast(u + di as f32 * offset, v + dj as f32 * offset, from).filter(
                                |&(depth, rim_normal)| {
                                    // (The side's texel width, widening with depth
                                    // in a perspective texture.)
                                    let spread = c.centre_distance().map_or(1.0, |h| (h + depth) / h);
                                    let step = offset * across.length() * spread;
                                    let same_way = rim_normal.dot(got) >= RIM_MAX_TURN_DEG.to_radians().cos();
                                    depth > rounded
                                        && depth - rounded <= join_reach(slope, step, quantum)
                                        && same_way
                                },
                            );
                            if let Some((depth, _)) = own {
                                want = want.max(depth);
                                break;
                            }
                        }
                    }
                    agreement.rim_deepened += usize::from(want > centre_depth + quantum);
                    let stored = (point - c.point(u, v, 0.0)).dot(c.f);
                    if (stored - want).abs() > quantum * 1.01 + 1e-6 {
                        agreement.depth_mismatch += 1;
                    }
                }
                _ => agreement.mask_mismatch += 1,
            }
        }
    }
    agreement
}

fn assert_agrees(a: &Agreement, what: &str) {
    eprintln!("{what}: {a:?}");
    assert!(
        a.covered > a.texels / 20,
        "{what}: too few covered texels to test: {a:?}"
    );
    // Rays grazing an edge may land on either side; allow a handful out of thousands.
    let allowed = (a.texels / 2000).max(2);
    assert!(a.mask_mismatch <= allowed, "{what}: mask {a:?}");
    assert!(a.depth_mismatch <= allowed, "{what}: depth {a:?}");
    assert!(a.normal_mismatch <= allowed, "{what}: normals {a:?}");
    // (The rim rule is exercised: every object here has a curved outline.)
    assert!(a.rim_deepened > 0, "{what}: no rim texel deepened {a:?}");
}

#[test]
fn default_scene_objects_round_trip() {
    for (object, eye) in [("sphere", "-1,3,6"), ("knot", "6,2.5,4"), ("tree", "3,4,-1")] {
        for bits in [8, 16] {
            let a = check("default", object, eye, 64, bits);
            assert_agrees(&a, &format!("{object}/{bits}"));
        }
        // (The tree's eye above is too near it for a perspective texture: one further.)
        let eye = if object == "tree" { "8,5,-4" } else { eye };
        let a = check_in("default", object, eye, 64, 8, "perspective");
        assert_agrees(&a, &format!("{object}/perspective"));
    }
}

/// A small OBJ with no normals, degenerate triangles and a quad.
fn write_awkward_obj(dir: &Path) -> std::path::PathBuf {
    let path = dir.join("awkward.obj");
    let mut text = String::from("# no normals, degenerate faces\n");
    let n = 12;
    for j in 0..=n {
        for i in 0..=n {
            let (x, z) = (i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5);
            let y = 0.3 * (6.0 * x).sin() * (5.0 * z).cos();
            text += &format!("v {x} {y} {z}\n");
        }
    }
    let at = |i: usize, j: usize| j * (n + 1) + i + 1;
    for j in 0..n {
        for i in 0..n {
            text += &format!(
                "f {} {} {} {}\n",
                at(i, j),
                at(i, j + 1),
                at(i + 1, j + 1),
                at(i + 1, j)
            );
        }
    }
    text += &format!("f {} {} {}\n", at(0, 0), at(0, 0), at(1, 1)); // repeated corner
    text += &format!("f {} {} {}\n", at(0, 0), at(1, 0), at(2, 0)); // collinear
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn obj_without_normals_and_with_degenerate_faces_round_trips() {
    let dir = scratch("awkward");
    let obj = write_awkward_obj(&dir);
    let spec = obj.to_str().unwrap();
    for (eye, bits) in [("0.4,2,1.5", 8), ("-2,0.3,0.2", 16), ("0,3,0.001", 8)] {
        let a = check(spec, "awkward", eye, 48, bits);
        assert_agrees(&a, &format!("awkward from {eye}"));
    }
}

#[test]
fn shared_real_meshes_round_trip() {
    let models = shared_models();
    for name in ["suzanne", "spot", "fandisk", "stanford-bunny"] {
        let path = models.join(format!("{name}.obj"));
        assert!(path.is_file(), "{} is missing", path.display());
        let scene = Scene::load(path.to_str().unwrap()).unwrap();
        let b = scene.objects[0].local_bounds;
        let eye = b.center() + Vec3::new(0.7, 0.5, 1.0).normalize() * b.extent().length() * 2.0;
        let eye = format!("{},{},{}", eye.x, eye.y, eye.z);
        let a = check(path.to_str().unwrap(), name, &eye, 40, 8);
        assert_agrees(&a, name);
    }
}
