//! `relief reference` against values computed by hand.

use relief_tests::{relief, scratch};

/// Writes the test scene (a lit unit sphere on blue) into `dir`.
fn ball_scene(dir: &std::path::Path) -> std::path::PathBuf {
    let scene_path = dir.join("ball.toml");
    std::fs::write(
        &scene_path,
        r#"
        background = [0, 0, 1]
        ambient = [0.1, 0.1, 0.1]
        [[lights]]
        kind = "directional"
        direction = [0, 0, -1]
        intensity = 0.8
        [[objects]]
        name = "ball"
        generator = { kind = "sphere", subdivisions = 6 }
        diffuse = [0.5, 0.25, 0.75]
        specular = 0.3
        shininess = 10
        "#,
    )
    .unwrap();
    scene_path
}

/// `relief reference` of the ball from (0, 0, 4), 65×49 pixels, `samples` rays per pixel
/// edge.
fn ball_reference(dir: &std::path::Path, samples: u32) -> image::RgbImage {
    let scene_path = ball_scene(dir);
    let png = dir.join(format!("frame-{samples}.png"));
    let out = relief(&[
        "reference",
        "--scene",
        scene_path.to_str().unwrap(),
        "--eye",
        "0,0,4",
        "--target",
        "0,0,0",
        "--fov",
        "40",
        "--size",
        "65x49",
        "--samples",
        &samples.to_string(),
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let image = image::open(&png).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (65, 49));
    image
}

/// A unit sphere seen straight on: the centre pixel shows the point nearest the eye,
/// whose normal points back at the eye, lit by the scene's one light — its colour
/// worked by hand from the scene file, not by the lighting code under test.
#[test]
fn sphere_centre_pixel_matches_the_lighting_model() {
    let dir = scratch("reference");
    let image = ball_reference(&dir, 1);
    // Phong at the point nearest the eye: normal, light and view all +z, so n·l = 1 and
    // the mirror direction is the view (r·v = 1, and 1^10 = 1). Per channel:
    // ambient·albedo + intensity·(albedo·(n·l) + specular):
    //   red   0.1·0.5  + 0.8·(0.5  + 0.3) = 0.69  → 176
    //   green 0.1·0.25 + 0.8·(0.25 + 0.3) = 0.465 → 119
    //   blue  0.1·0.75 + 0.8·(0.75 + 0.3) = 0.915 → 233
    let want = [176u8, 119, 233];
    let got = image.get_pixel(32, 24).0;
    for c in 0..3 {
        assert!(
            (got[c] as i32 - want[c] as i32).abs() <= 2,
            "centre {got:?}, expected {want:?}"
        );
    }
    // Corners see the background.
    assert_eq!(image.get_pixel(0, 0).0, [0, 0, 255]);
    // The sphere's silhouette: radius 1 at distance 4 subtends asin(1/4); its image
    // radius is tan(asin(1/4)) / tan(20°) of the half-height.
    let radius_px = (0.25f32.asin().tan() / 20f32.to_radians().tan()) * 24.5;
    let covered = image.pixels().filter(|p| p.0 != [0, 0, 255]).count() as f32;
    let expected = std::f32::consts::PI * radius_px * radius_px;
    assert!(
        (covered - expected).abs() / expected < 0.05,
        "covered {covered}, expected {expected}"
    );
}

/// With 3×3 rays per pixel, pixels inside the sphere's image keep their colour (smooth
/// shading varies little within a pixel), while silhouette pixels blend sphere and
/// background — and the blend keeps the image's total: the blue the sphere takes away
/// is the same as point-sampled, within 3 %.
#[test]
fn antialiased_reference_blends_only_the_silhouette() {
    let dir = scratch("reference-aa");
    let (point, smooth) = (ball_reference(&dir, 1), ball_reference(&dir, 3));
    let background = [0u8, 0, 255];
    let is_ball = |x: u32, y: u32| point.get_pixel(x, y).0 != background;
    let (mut interior, mut blended) = (0, 0);
    for y in 1..48 {
        for x in 1..64 {
            let all_ball = (-1i32..=1)
                .all(|dy| (-1i32..=1).all(|dx| is_ball((x as i32 + dx) as u32, (y as i32 + dy) as u32)));
            let (p, s) = (point.get_pixel(x, y).0, smooth.get_pixel(x, y).0);
            let differs = (0..3)
                .map(|c| (p[c] as i32 - s[c] as i32).abs())
                .max()
                .unwrap_or(0);
            if all_ball {
                interior += 1;
                assert!(differs <= 3, "interior pixel {x},{y}: {p:?} vs {s:?}");
            } else if differs > 16 {
                blended += 1;
            }
        }
    }
    assert!(
        interior > 500 && blended > 20,
        "interior {interior}, blended {blended}"
    );
    let radius_px = (0.25f32.asin().tan() / 20f32.to_radians().tan()) * 24.5;
    let expected = std::f32::consts::PI * radius_px * radius_px;
    let covered: f32 = smooth.pixels().map(|p| (255.0 - p.0[2] as f32) / 255.0).sum();
    let point_covered: f32 = point.pixels().map(|p| (255.0 - p.0[2] as f32) / 255.0).sum();
    assert!(
        (covered - point_covered).abs() / point_covered < 0.03,
        "blue deficit {covered} (antialiased) vs {point_covered} (point), sphere area {expected} px"
    );
}

#[test]
fn a_bad_output_path_fails_before_the_work_and_leaves_nothing() {
    let dir = scratch("reference-out");
    let scene = ball_scene(&dir);
    let scene = scene.to_str().unwrap();
    let run = |out: &str| {
        relief(&[
            "reference",
            "--scene",
            scene,
            "--eye",
            "0,0,4",
            "--target",
            "0,0,0",
            "--size",
            "16x12",
            "--out",
            out,
        ])
    };
    // Not a PNG name: a usage error (exit 2) naming the output.
    let jpg = dir.join("r.jpg");
    let wrong = run(jpg.to_str().unwrap());
    assert_eq!(wrong.status.code(), Some(2), "{wrong:?}");
    assert!(
        String::from_utf8_lossy(&wrong.stderr).contains("png"),
        "{wrong:?}"
    );
    assert!(!jpg.exists());
    // A directory that cannot be made: an error naming --out, before any tracing.
    let unwritable = run("/proc/relief-nope/r.png");
    let stderr = String::from_utf8_lossy(&unwritable.stderr);
    assert!(
        !unwritable.status.success() && stderr.contains("--out"),
        "{stderr}"
    );
    // The reason is said once.
    assert_eq!(stderr.matches("os error").count(), 1, "{stderr}");
}

/// Every pixel's object in a point-sampled reference, against the independent ray
/// caster through the pixel's centre: a low-poly sphere and knot before the eye (traced
/// as beams, few triangles to the pixel) and a ground plane reaching behind it (traced
/// ray by ray) that hides the sphere's lower part, so the nearest across the two ways
/// decides what covers what. Pixels whose centre ray grazes an edge may differ.
#[test]
fn each_pixel_shows_the_object_the_oracle_finds() {
    use glam::Vec3;
    use relief_core::{camera::Camera, scene::Scene};
    use relief_trace::{SceneTracer, render_reference};

    let dir = scratch("reference-objects");
    let scene_path = dir.join("few.toml");
    std::fs::write(
        &scene_path,
        r#"
        [[objects]]
        name = "ground"
        generator = { kind = "plane", size = 40.0, divisions = 1 }
        [[objects]]
        name = "ball"
        generator = { kind = "sphere", subdivisions = 2 }
        translate = [-0.6, 0.4, 0.0]
        [[objects]]
        name = "knot"
        generator = { kind = "knot", p = 2, q = 3, segments = 48, sides = 8, tube_radius = 0.25 }
        translate = [0.8, 1.2, -0.5]
        scale = 0.8
        "#,
    )
    .unwrap();
    let scene = Scene::load(scene_path.to_str().unwrap()).unwrap();
    let camera = Camera::look_at(
        Vec3::new(0.5, 1.8, 4.5),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::Y,
        40.0,
        160,
        90,
    )
    .unwrap();
    let tracer = SceneTracer::new(&scene);
    // (With 3×3 samples the pixel's object is its middle sample's: the centre ray's.)
    for samples in [1, 3] {
        each_pixel_object_matches(&scene, &render_reference(&tracer, &camera, samples), &camera);
    }
}

/// Every pixel of `frame` names the object the oracle's centre ray finds (see
/// [`each_pixel_shows_the_object_the_oracle_finds`]).
fn each_pixel_object_matches(
    scene: &relief_core::scene::Scene,
    frame: &relief_core::frame::Frame,
    camera: &relief_core::camera::Camera,
) {
    use relief_core::frame::NO_OBJECT;
    use relief_tests::oracle::nearest_hit;
    let (mut objects_seen, mut differ) = ([0usize; 3], Vec::new());
    for y in 0..camera.height {
        for x in 0..camera.width {
            let direction = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
            let nearest = scene
                .objects
                .iter()
                .enumerate()
                .filter_map(|(k, o)| Some((k, nearest_hit(&o.mesh, o.to_local(camera.eye), direction)?)))
                .min_by(|a, b| a.1.t.total_cmp(&b.1.t));
            let want = nearest.map_or(NO_OBJECT, |(k, _)| k as u32);
            let got = frame.object[(y * camera.width + x) as usize];
            if let Some(k) = (got != NO_OBJECT).then_some(got as usize) {
                objects_seen[k] += 1;
            }
            let grazing = nearest.is_some_and(|(_, h)| h.u.min(h.v).min(1.0 - h.u - h.v) < 1e-4);
            if got != want && !grazing {
                differ.push((x, y, got, want));
            }
        }
    }
    assert!(
        objects_seen.iter().all(|&n| n > 200),
        "each object should cover a good part of the frame: {objects_seen:?}"
    );
    assert!(differ.is_empty(), "pixels (x, y, drawn, oracle's): {differ:?}");
}
