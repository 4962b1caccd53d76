//! `relief reference` against values computed by hand.

use glam::Vec3;

use relief_core::scene::Scene;
use relief_core::shading::to_rgb8;
use relief_tests::{relief, scratch};

/// A unit sphere seen straight on: the centre pixel shows the point nearest the eye,
/// whose normal points back at the eye, lit by the scene's lights.
#[test]
fn sphere_centre_pixel_matches_the_lighting_model() {
    let dir = scratch("reference");
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
    let png = dir.join("frame.png");
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
        "--out",
        png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let image = image::open(&png).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (65, 49));
    let scene = Scene::load(scene_path.to_str().unwrap()).unwrap();
    let o = &scene.objects[0];
    let eye = Vec3::new(0.0, 0.0, 4.0);
    let want = to_rgb8(
        scene
            .lighting
            .shade(Vec3::new(0.5, 0.25, 0.75), Vec3::Z, Vec3::Z, eye, o.specular),
    );
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
