//! The display methods against the ray-traced reference, a few degrees from the eye
//! their texture was baked for — and the one-pass pre-warp against the two-pass one it
//! must equal almost everywhere.

use relief_core::relief::{DepthBits, SourceProjection};
use relief_core::scene::Scene;
use relief_lab::methods::Method;
use relief_lab::report::{GEOMETRY, Options, Row, error_vs_time};
use relief_lab::solo::Solo;
use relief_render::impostor::Impostor;
use relief_render::warp::params::WarpParams;
use relief_render::warp::prewarp::{Variant, prewarp};

fn row<'a>(rows: &'a [Row], object: &str, method: Method, angle: f32) -> &'a Row {
    rows.iter()
        .find(|r| r.object == object && r.method == method.name() && r.angle_deg == angle)
        .unwrap_or_else(|| panic!("no row for {object} {} {angle}°", method.name()))
}

/// Every method but the sprite shows a convex and a self-occluding object 5° from the
/// source eye within a few dB of what it shows at the source eye, above what the
/// unwarped sprite shows there; the pre-warp variants agree with each other. The
/// pre-warp's texture mapping blends its silhouette pixels by coverage, so it is judged
/// against the anti-aliased reference; the other methods draw whole pixels and are
/// judged against the one-sample one.
#[test]
fn every_method_follows_a_turned_eye() {
    let scene = Scene::load("default").expect("default scene");
    let objects = ["sphere".to_string(), "knot".to_string()];
    let options = Options {
        sizes: vec![128],
        angles: vec![0.0, 5.0],
        methods: Method::ALL.to_vec(),
        runs: 1,
        frame_size: 128,
        distance: 3.0,
        strip: (5.0, 128),
    };
    let rows = error_vs_time(&scene, &objects, &options, |_| {})
        .expect("measured")
        .rows;
    let prewarps = [
        Method::TwoPass1d,
        Method::TwoPassAsym,
        Method::TwoPassComp,
        Method::Interleaved,
    ];
    // Measured when written (PSNR dB at 5°): sphere 44.7–48.3 against the one-sample
    // reference, the pre-warps 33.0–33.1 against the anti-aliased one (sprite 31.8);
    // knot 27.0–31.9 and 31.3–31.4 (sprite 26.7). The floors leave ~2 dB for platform
    // noise; the sphere looks much the same from 5° round, so its sprite is close.
    for (object, point_floor, aa_floor, over_sprite) in
        [("sphere", 42.0, 31.0, 0.5), ("knot", 24.5, 29.0, 3.0)]
    {
        let sprite = row(&rows, object, Method::Sprite, 5.0).psnr_aa_db;
        for method in Method::ALL.into_iter().filter(|&m| m != Method::Sprite) {
            let turned = row(&rows, object, method, 5.0);
            let blends = prewarps.contains(&method);
            let (psnr, floor) = if blends {
                (turned.psnr_aa_db, aa_floor)
            } else {
                (turned.psnr_db, point_floor)
            };
            eprintln!(
                "{object} {}: {psnr:.2} dB at 5° (sprite {sprite:.2})",
                method.name()
            );
            assert!(
                psnr >= floor && turned.hole_frac < 0.06,
                "{object} {}: {turned:?}",
                method.name()
            );
            if blends {
                assert!(
                    psnr >= sprite + over_sprite,
                    "{object} {}: {psnr} vs sprite {sprite}",
                    method.name()
                );
            }
        }
        let geometry = rows
            .iter()
            .find(|r| r.object == object && r.method == GEOMETRY && r.angle_deg == 5.0)
            .expect("geometry row");
        assert!(geometry.psnr_db > 50.0, "{geometry:?}");
    }
}

/// The interleaved pre-warp (one pass, each row sample straight into its column) and
/// the asymmetric two-pass one (through an intermediate image keeping each column's
/// last row sample) make the same texels except where one row writes a column twice:
/// where it folds over itself, and at the start of a run of connected texels (the first
/// lands in its pixel, the span to the second may write that pixel again). Measured
/// when written: 98.5 % (sphere, 10°), 98.6 % (knot, 10°), 96.6 % (knot, −25°).
#[test]
fn one_pass_and_two_pass_prewarps_agree() {
    let scene = Scene::load("default").expect("default scene");
    for (object, angle, least) in [
        ("sphere", 10.0, 0.97),
        ("knot", 10.0, 0.97),
        ("knot", -25.0, 0.95),
    ] {
        let solo = Solo::new(&scene, object, 3.0).expect("solo");
        let impostor = Impostor::new(solo.bake(solo.eye(0.0), 128, DepthBits::Eight).expect("bake"));
        let params = WarpParams::new(&impostor.texture, solo.eye(angle)).expect("params");
        let one = prewarp(&impostor, &params, Variant::Interleaved);
        let two = prewarp(&impostor, &params, Variant::Asymmetric);
        assert_eq!(
            (one.u0, one.v0, one.width, one.height),
            (two.u0, two.v0, two.width, two.height)
        );
        let filled = one.texels.iter().filter(|t| !t.is_empty()).count();
        let same = one
            .texels
            .iter()
            .zip(&two.texels)
            .filter(|(a, b)| !a.is_empty() && a == b)
            .count();
        let share = same as f64 / filled as f64;
        eprintln!("{object} {angle}°: {same} of {filled} filled texels equal ({share:.4})");
        assert!(filled > 3000 && share >= least, "{object} {angle}°: {share}");
    }
}

/// A pre-warp through a window of the plane (what a screen sees) makes, over the
/// window and its margin, exactly the texels the whole pre-warp makes there — from
/// fewer texels visited — for every variant, windows inside, across and outside the
/// image, epipoles inside and far off to a side.
#[test]
fn a_windowed_prewarp_equals_the_whole_one_where_it_reaches() {
    use relief_render::warp::prewarp::{PlaneWindow, PrewarpImage, prewarp_split};
    let scene = Scene::load("default").expect("default scene");
    let windows = [
        (10.0, 20.0, 60.0, 50.0),
        (-40.0, 100.0, 30.0, 200.0),
        (90.0, -30.0, 400.0, 70.0),
        (0.5, 0.5, 127.5, 127.5),
        // (Past every texel's reach: nothing to compare, but it must make nothing.)
        (300.0, 300.0, 400.0, 400.0),
    ];
    let mut cropped = 0;
    let cases = [
        ("knot", 10.0),
        ("knot", -25.0),
        ("rock", 40.0),
        ("tree", 3.0),
        ("deep plane", 20.0),
    ];
    for (object, angle) in cases {
        let solo =
            Solo::new(&scene, if object == "deep plane" { "knot" } else { object }, 3.0).expect("solo");
        let mut texture = solo.bake(solo.eye(0.0), 128, DepthBits::Eight).expect("bake");
        if object == "deep plane" {
            // Every texel at the deepest level, each its own colour: every texel lands
            // as far in as any can, so the first that can reach a window often does,
            // and the span from the one before must be made.
            let deepest = texture.depth_bits.max_level();
            for (k, (depth, albedo)) in texture.depth.iter_mut().zip(&mut texture.albedo).enumerate() {
                *depth = deepest;
                *albedo = [(k * 7) as u8, (k * 13) as u8, (k / 128 * 5) as u8];
            }
        }
        let impostor = Impostor::new(texture);
        let params = WarpParams::new(&impostor.texture, solo.eye(angle)).expect("params");
        for variant in Variant::ALL {
            let whole = prewarp(&impostor, &params, variant);
            // (Outside an image and empty in it are the same: nothing there.)
            let at = |image: &PrewarpImage, u: i32, v: i32| {
                image
                    .at(u as f32 + 0.5, v as f32 + 0.5)
                    .filter(|t| !t.is_empty())
                    .copied()
            };
            for (u0, v0, u1, v1) in windows {
                let window = PlaneWindow { u0, v0, u1, v1 };
                let part = prewarp_split(&impostor, &params, variant, Some(&window));
                cropped += usize::from(part.texels.len() < whole.texels.len());
                // The window's own texels and its margin's.
                let (wu1, wv1) = (whole.u0 + whole.width as i32, whole.v0 + whole.height as i32);
                let (x0, x1) = (
                    (u0.floor() as i32 - 2).max(whole.u0),
                    (u1.ceil() as i32 + 2).min(wu1),
                );
                let (y0, y1) = (
                    (v0.floor() as i32 - 2).max(whole.v0),
                    (v1.ceil() as i32 + 2).min(wv1),
                );
                for v in y0..y1 {
                    for u in x0..x1 {
                        assert_eq!(
                            at(&part, u, v),
                            at(&whole, u, v),
                            "{object} {angle}° {variant:?} window {window:?} texel ({u}, {v})"
                        );
                    }
                }
            }
        }
    }
    // (Every window but the one holding the whole quad crops something.)
    assert!(cropped >= 5 * 4 * 4, "{cropped}");
}

/// Cameras near a textured object, looking at it, past it and away from it: the
/// window a camera sees holds the plane point of every pixel whose ray crosses the
/// plane within the pre-warp's reach (computed per pixel as the texture mapping does)
/// and is no larger than they need; a frame drawn through the window is the frame
/// drawn from the whole pre-warp, pixel for pixel.
#[test]
fn the_window_a_camera_sees_leaves_out_only_what_it_cannot_show() {
    use glam::Vec3;
    use relief_core::camera::Camera;
    use relief_lab::methods::display;
    use relief_render::gbuffer::GBuffer;
    use relief_render::warp::prewarp::{PlaneWindow, prewarp_split};
    use relief_render::warp::texmap;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "knot", 3.0).expect("solo");
    let impostor = Impostor::new(solo.bake(solo.eye(0.0), 128, DepthBits::Eight).expect("bake"));
    let c = impostor.texture.camera;
    let centre = solo.scene.objects[0].local_bounds.center();
    let radius = solo.scene.objects[0].local_bounds.extent().length() / 2.0;
    let mut tested = 0;
    // Eye distance and aim (in radii from the centre), and the most of the image the
    // window may keep (measured when written: all, 63 %, 54 %, 44 %, one texel twice).
    for (k, (distance, aim, most)) in [
        (3.0, Vec3::ZERO, 1.0),
        (1.6, Vec3::new(0.6, 0.0, 0.0), 0.7),
        (1.4, Vec3::new(-0.5, 0.4, 0.0), 0.6),
        (1.3, Vec3::new(0.0, -0.9, 0.3), 0.5),
        (2.0, Vec3::new(3.0, 0.0, 0.0), 0.0),
        (1.5, Vec3::new(0.0, 0.0, 2.0), 0.0),
    ]
    .into_iter()
    .enumerate()
    {
        let eye = centre + (solo.eye(4.0 * k as f32) - centre).normalize() * radius * distance;
        let camera = Camera::look_at(eye, centre + aim * radius, Vec3::Y, 50.0, 160, 120).expect("camera");
        let params = WarpParams::new(&impostor.texture, eye).expect("params");
        let window = PlaneWindow::seen_by(&camera, &c).expect("finite");
        // Every pixel's plane point within reach (one quad past the quad).
        let (w, h) = (c.width as f32, c.height as f32);
        let (a_scale, b_scale) = (c.a / c.a.length_squared(), c.b / c.b.length_squared());
        let mut hit = PlaneWindow {
            u0: f32::MAX,
            v0: f32::MAX,
            u1: f32::MIN,
            v1: f32::MIN,
        };
        for y in 0..camera.height {
            for x in 0..camera.width {
                let ray = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                let towards = ray.dot(c.f);
                if towards <= 0.0 {
                    continue;
                }
                let s = params.h / towards;
                let (u, v) = (
                    params.foot.x + s * ray.dot(a_scale),
                    params.foot.y + s * ray.dot(b_scale),
                );
                if u < -w || u > 2.0 * w || v < -h || v > 2.0 * h {
                    continue;
                }
                assert!(
                    u >= window.u0 - 0.01
                        && u <= window.u1 + 0.01
                        && v >= window.v0 - 0.01
                        && v <= window.v1 + 0.01,
                    "camera {k}: pixel ({x}, {y}) sees ({u}, {v}) outside {window:?}"
                );
                hit = PlaneWindow {
                    u0: hit.u0.min(u),
                    v0: hit.v0.min(v),
                    u1: hit.u1.max(u),
                    v1: hit.v1.max(v),
                };
            }
        }
        // No larger than the pixels need (plus the half pixel to the screen's edge).
        let slack = 0.05 * (w + h);
        assert!(
            window.u0 >= hit.u0 - slack
                && window.u1 <= hit.u1 + slack
                && window.v0 >= hit.v0 - slack
                && window.v1 <= hit.v1 + slack,
            "camera {k}: {window:?} against the pixels' {hit:?}"
        );
        let whole = prewarp_split(&impostor, &params, Variant::Interleaved, None);
        let part = prewarp_split(&impostor, &params, Variant::Interleaved, Some(&window));
        let kept = part.texels.len() as f32 / whole.texels.len() as f32;
        assert!(part.texels.len() == 1 || kept <= most, "camera {k} keeps {kept}");
        assert!(
            (part.texels.len() == 1) == (most == 0.0),
            "camera {k} keeps {kept}"
        );
        let mut expected = GBuffer::new(camera.width, camera.height);
        let depths = texmap::Depths {
            tested: 1.0,
            world: 1.0,
        };
        texmap::map(
            &whole,
            &impostor.texture,
            &params,
            depths,
            0,
            &camera,
            &mut expected,
        );
        let mut got = GBuffer::new(camera.width, camera.height);
        display(Method::Interleaved, &impostor, 0, &camera, &mut got).expect("display");
        let (expected, got) = (
            expected.shade(&solo.scene, &camera),
            got.shade(&solo.scene, &camera),
        );
        tested += got.object.iter().filter(|&&o| o == 0).count();
        assert!(
            expected.color == got.color && expected.object == got.object,
            "camera {k}"
        );
    }
    // (The frames show the object.)
    assert!(tested > 10_000, "{tested} pixels");
}

/// Texture mapping covers what the surface covers: a square filling its 8×8 texture
/// (a texel is ~5 pixels here), shown from the texture's own eye, covers the pixels the
/// rasterized square does — to its edges, the outermost half texel included — with no
/// hole inside: every pixel where the two differ lies on the square's outline.
#[test]
fn texture_mapping_covers_a_full_texture_to_its_edges() {
    use glam::Vec3;
    use relief_core::camera::Camera;
    use relief_core::mesh::{Material, Mesh};
    use relief_core::scene::SceneObject;
    use relief_core::shading::Specular;
    use relief_lab::methods::display;
    use relief_render::gbuffer::GBuffer;
    use relief_render::raster::rasterize;
    use relief_trace::bake;
    use relief_trace::tracer::ObjectTracer;

    let square = Mesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        materials: vec![Material::default()],
        ..Default::default()
    };
    let object = SceneObject::new("square", square, glam::DVec3::ZERO, Specular::default());
    let eye = Vec3::new(0.0, 0.0, 4.0);
    let texture = bake(
        &ObjectTracer::new(&object),
        eye,
        8,
        DepthBits::Eight,
        SourceProjection::Orthographic,
    )
    .expect("bake");
    assert_eq!(texture.covered_texels(), 64, "the square fills its texture");
    let camera = Camera::look_at(eye, Vec3::ZERO, Vec3::Y, 50.0, 96, 72).expect("camera");
    let mut geometry = GBuffer::new(96, 72);
    rasterize(&[(0, &object)], &camera, 0.01, &mut geometry);
    let mut impostor = GBuffer::new(96, 72);
    display(
        Method::Interleaved,
        &Impostor::new(texture),
        0,
        &camera,
        &mut impostor,
    )
    .expect("display");
    let covered = |g: &GBuffer, x: i64, y: i64| {
        (0..96).contains(&x) && (0..72).contains(&y) && g.get(x as u32, y as u32).is_covered()
    };
    let (mut both, mut differ) = (0, 0);
    for y in 0..72 {
        for x in 0..96 {
            let truth = covered(&geometry, x, y);
            if truth == covered(&impostor, x, y) {
                both += truth as usize;
                continue;
            }
            differ += 1;
            let on_outline = [(-1, 0), (1, 0), (0, -1), (0, 1)]
                .iter()
                .any(|&(dx, dy)| covered(&geometry, x + dx, y + dy) != truth);
            assert!(on_outline, "pixel ({x}, {y}): geometry {truth}, impostor not");
        }
    }
    assert!(both > 1200, "{both} pixels covered by both");
    eprintln!("{both} pixels covered by both, {differ} on the outline differ");
}

/// Shows `impostor` (object 0) from `camera` into `gbuffer` behind what is there:
/// depth-tested as if `factor` (> 1) times farther ([`Prewarped::behind`]).
fn draw_behind(
    impostor: &Impostor,
    camera: &relief_core::camera::Camera,
    factor: f32,
    gbuffer: &mut relief_render::gbuffer::GBuffer,
) {
    use relief_render::warp::Prewarped;
    let prewarped = Prewarped::new(Variant::Interleaved, impostor, camera).expect("pre-warp");
    let behind = prewarped.behind(factor).expect("behind");
    behind.draw(impostor, 0, camera, gbuffer);
}

/// A texture drawn behind another ([`Prewarped::behind`]) fills in what the first
/// leaves empty: the sphere's textures baked 60° apart, seen from halfway between —
/// where the first texture drew, the frame is as it alone left it (but for a few
/// pixels at the silhouette, where the first's grazing samples stray in depth), and
/// the second adds the side of the sphere the first never saw.
#[test]
fn a_texture_drawn_behind_fills_what_the_first_leaves_empty() {
    use relief_render::gbuffer::GBuffer;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "sphere", 3.0).expect("solo");
    let bake =
        |degrees: f32| Impostor::new(solo.bake(solo.eye(degrees), 128, DepthBits::Eight).expect("bake"));
    let (first, second) = (bake(0.0), bake(60.0));
    let camera = solo.camera(solo.eye(30.0), 256).expect("orbit camera");
    let mut alone = GBuffer::new(256, 256);
    relief_render::warp::display(Variant::Interleaved, &first, 0, &camera, &mut alone).expect("shown");
    let mut both = alone.clone();
    draw_behind(&second, &camera, 1.02, &mut both);
    let mut reference = GBuffer::new(256, 256);
    relief_render::raster::rasterize(&[(0, &solo.scene.objects[0])], &camera, 0.01, &mut reference);
    let (mut kept, mut changed, mut added) = (0, 0, 0);
    for y in 0..256 {
        for x in 0..256 {
            let (a, b) = (alone.get(x, y), both.get(x, y));
            if a.is_covered() {
                kept += 1;
                changed += usize::from(a != b);
            } else if b.is_covered() {
                added += 1;
            }
        }
    }
    // Missing: what the sphere covers that the shaded frame does not count as the
    // sphere's (silhouette pixels count where their fragments cover more than half).
    let shown = |g: &GBuffer| g.shade(&solo.scene, &camera).object;
    let (alone, both, truth) = (shown(&alone), shown(&both), shown(&reference));
    let missing = |frame: &[u32]| {
        frame
            .iter()
            .zip(&truth)
            .filter(|&(&f, &t)| t == 0 && f != 0)
            .count()
    };
    let (missing_alone, missing_both) = (missing(&alone), missing(&both));
    eprintln!(
        "{kept} drawn by the first ({changed} changed by the second), {added} added; \
         sphere pixels missing: {missing_alone} alone, {missing_both} with the second"
    );
    assert!(kept > 10_000 && added > 300, "{kept} kept, {added} added");
    assert!(changed * 200 < kept, "{changed} of {kept} changed");
    assert!(
        missing_both * 5 < missing_alone,
        "{missing_both} of {missing_alone} still missing"
    );
}

/// A partner drawn behind the shown texture at the level the screen needs (texels no
/// larger than its pixels: `Pyramid::level_for` at `MAX_TEXEL_PIXELS`, as the client's
/// manager draws one, front faces only for a closed surface as it does) fills the side
/// of the object the shown texture never saw; a level coarser draws its own coarser
/// outline where the shown one has nothing, and gives back much of the gain. The knot's
/// 256² textures (with their pyramids) 0° and 35° round, seen from 25°, in a 256² frame
/// against the anti-aliased reference, over the knot's own pixels (when written: 27.79
/// dB alone, 31.21 with the partner, 29.17 with it a level coarser).
#[test]
fn a_partner_at_the_screens_level_scores_above_one_a_level_coarser() {
    use relief_lab::image_error::object_psnr;
    use relief_render::gbuffer::GBuffer;
    use relief_render::impostor::Faces;
    use relief_render::pyramid::{MAX_TEXEL_PIXELS, MIN_LEVEL_EDGE, Pyramid};
    use relief_render::warp::display;
    use relief_trace::ANTIALIASED_SAMPLES;

    /// Eyes' distance from the knot's centre, in bounding radii.
    const ORBIT_RADII: f32 = 3.0;
    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "knot", ORBIT_RADII).expect("solo");
    let faces = Faces::of(&solo.scene.objects[0]);
    let pyramid = |degrees: f32| {
        let texture = solo
            .bake(solo.eye(degrees), 256, DepthBits::Sixteen)
            .expect("bake");
        Pyramid::new(texture, MIN_LEVEL_EDGE).with_faces(faces)
    };
    let (shown, partner) = (pyramid(0.0), pyramid(35.0));
    let camera = solo.camera(solo.eye(25.0), 256).expect("orbit camera");
    let reference = solo.reference(&camera, ANTIALIASED_SAMPLES);
    // As the client's `partner_depth_factor` puts a partner behind: `PARTNER_BEHIND`
    // (5 %) of the bounding radius over the eye's distance.
    let behind = 1.0 + 0.05 / ORBIT_RADII;
    let shown_level = shown.level_for(&camera, MAX_TEXEL_PIXELS);
    let psnr = |partner_level: Option<usize>| {
        let mut gbuffer = GBuffer::new(256, 256);
        display(
            Variant::Interleaved,
            &shown.levels[shown_level],
            0,
            &camera,
            &mut gbuffer,
        )
        .expect("shown");
        if let Some(level) = partner_level {
            draw_behind(&partner.levels[level], &camera, behind, &mut gbuffer);
        }
        object_psnr(&gbuffer.shade(&solo.scene, &camera), &reference, 0).expect("knot shown")
    };
    let screen_level = partner.level_for(&camera, MAX_TEXEL_PIXELS);
    assert!(
        screen_level + 1 < partner.levels.len(),
        "a coarser level to compare with"
    );
    let alone = psnr(None);
    let at_screen = psnr(Some(screen_level));
    let coarser = psnr(Some(screen_level + 1));
    eprintln!(
        "knot: alone {alone:.2} dB, partner at the screen's level {at_screen:.2}, a level coarser {coarser:.2}"
    );
    assert!(
        at_screen > alone + 1.0,
        "{at_screen:.2} dB with the partner, {alone:.2} alone"
    );
    assert!(
        coarser < at_screen - 0.75,
        "{coarser:.2} dB a level coarser, {at_screen:.2} at the screen's"
    );
}

/// A silhouette lies where the surface's samples put it, neither grown nor shrunk: the
/// sphere shown from its texture's own eye covers (more than half of each pixel, as the
/// shaded frame counts its silhouette's fragments), pixel for pixel, what the sphere
/// rasterized covers but for a thin band of its outline — on average within a fifth of
/// a pixel of it (measured: 0.07 and 0.12), where giving each run's end sample its
/// whole pre-warped pixel grew it by 0.44 (the rim, which the pre-warp compresses).
/// And over the sphere's own pixels, against the anti-aliased reference, it scores
/// within 2 dB of exact geometry drawn with one sample a pixel (measured: +0.5 and
/// −0.1 dB), where drawing each silhouette pixel whole, as its nearest texel, scored
/// 6.1 dB below it.
#[test]
fn a_silhouette_lies_where_its_samples_put_it() {
    use relief_lab::image_error::object_psnr;
    use relief_trace::ANTIALIASED_SAMPLES;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "sphere", 3.0).expect("solo");
    let size = 192;
    for (degrees, edge) in [(0.0, 128), (35.0, 160)] {
        let eye = solo.eye(degrees);
        let camera = solo.camera(eye, size).expect("orbit camera");
        let impostor = Impostor::new(solo.bake(eye, edge, DepthBits::Eight).expect("bake"));
        let (shown, exact) = impostor_and_geometry(&solo, &impostor, &camera);
        let (mut grown, mut shrunk, mut area) = (0i64, 0i64, 0i64);
        for (&a, &b) in shown.object.iter().zip(&exact.object) {
            let (a, b) = (a == 0, b == 0);
            grown += i64::from(a && !b);
            shrunk += i64::from(b && !a);
            area += i64::from(b);
        }
        // The outline's length, pixels, from the disc's area.
        let outline = 2.0 * (std::f64::consts::PI * area as f64).sqrt();
        let mean_growth = (grown - shrunk) as f64 / outline;
        let reference = solo.reference(&camera, ANTIALIASED_SAMPLES);
        let psnr = |frame| object_psnr(frame, &reference, 0).expect("the sphere shows");
        let (impostor_db, geometry_db) = (psnr(&shown), psnr(&exact));
        eprintln!(
            "{degrees}°, {edge}²: {grown} grown, {shrunk} shrunk, outline {outline:.0} px: \
             {mean_growth:.3} px; {impostor_db:.2} dB against geometry's {geometry_db:.2}"
        );
        assert!(mean_growth.abs() < 0.2, "grown by {mean_growth:.3} px on average");
        assert!(
            ((grown + shrunk) as f64) < 0.4 * outline,
            "{grown} grown and {shrunk} shrunk of {outline:.0} outline pixels"
        );
        assert!(
            impostor_db > geometry_db - 2.0,
            "{impostor_db:.2} dB against geometry's {geometry_db:.2}"
        );
    }
}

/// A texture seen turned keeps a smooth outline, whichever way it turns. At a grazing rim
/// each texel's centre ray strikes the surface anywhere up to `√(2r)` texels in front of
/// the outline, and turned, each texel moves by its depth: the outline became a row of
/// teeth on the side the eye turned to. With the bake's rim rays (`relief_trace::rim`)
/// the sphere's 128² texture, 17° round either way along its rows and its columns,
/// scores within half a dB of exact geometry or above it over the sphere's own pixels
/// (measured: +2.5, +2.7, +0.0, +1.0 dB), where from the centre rays alone it scored
/// −0.9 dB along its columns (+1.5, +1.7, −0.9, +0.5).
#[test]
fn a_turned_outline_stays_smooth() {
    use glam::{Quat, Vec3};
    use relief_lab::image_error::object_psnr;
    use relief_render::impostor::Faces;
    use relief_trace::ANTIALIASED_SAMPLES;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "sphere", 2.2).expect("solo");
    let centre = solo.scene.objects[0].local_bounds.center();
    let eye = solo.eye(0.0);
    let texture = solo.bake(eye, 128, DepthBits::Sixteen).expect("bake");
    let impostor = Impostor::new(texture).with_faces(Faces::Front);
    // Round the vertical axis (along the texture's rows), and round the horizontal one
    // square to the view (along its columns).
    let across = (eye - centre).cross(Vec3::Y).normalize();
    let mut gaps = Vec::new();
    for (axis, name) in [(Vec3::Y, "rows"), (across, "columns")] {
        for degrees in [-17.0f32, 17.0] {
            let turned = centre + Quat::from_axis_angle(axis, degrees.to_radians()) * (eye - centre);
            // (A texel of 0.7 pixels, within the pixel a client asks for:
            // `MAX_TEXEL_PIXELS`.)
            let camera = solo.camera(turned, 140).expect("orbit camera");
            let reference = solo.reference(&camera, ANTIALIASED_SAMPLES);
            let (shown, exact) = impostor_and_geometry(&solo, &impostor, &camera);
            let psnr = |frame| object_psnr(frame, &reference, 0).expect("the sphere shows");
            let gap = psnr(&shown) - psnr(&exact);
            eprintln!("along its {name}, {degrees}°: {gap:+.2} dB against geometry");
            gaps.push((name, degrees, gap));
        }
    }
    for (name, degrees, gap) in gaps {
        assert!(
            gap > -0.5,
            "along its {name}, {degrees}°: {gap:+.2} dB against geometry"
        );
    }
}

/// Near an object its outline stays in place with 16-bit depth. The pre-warp folds the
/// rim there (the eye sees less than the texture's half of the sphere), and many
/// texels land near the outline, which takes the outermost of them; 8-bit depth moves
/// each by its rounding, and the outline of a sphere at 2.4 of its radii swells. Over
/// the sphere's own pixels, against the anti-aliased reference, 16 bits score above
/// exact geometry drawn with one sample a pixel (measured: +1.3 dB) and 8 bits below
/// it (−1.7 dB).
#[test]
fn a_near_outline_keeps_its_place_with_sixteen_bit_depth() {
    use relief_lab::image_error::object_psnr;
    use relief_render::impostor::Faces;
    use relief_trace::ANTIALIASED_SAMPLES;

    // (A texel of 0.7–1.2 pixels, as a client shows: `MAX_TEXEL_PIXELS`.)
    const EDGE: u32 = 160;
    let scene = Scene::load("default").expect("default scene");
    // 1.4 bounding radii: 2.4 of the sphere's.
    let solo = Solo::new(&scene, "sphere", 1.4).expect("solo");
    let eye = solo.eye(0.0);
    let camera = solo.camera(eye, 240).expect("orbit camera");
    let reference = solo.reference(&camera, ANTIALIASED_SAMPLES);
    let measure = |bits| {
        // (As a client shows a closed surface: its front faces.)
        let texture = solo.bake(eye, EDGE, bits).expect("bake");
        let impostor = Impostor::new(texture).with_faces(Faces::of(&solo.scene.objects[0]));
        let (shown, exact) = impostor_and_geometry(&solo, &impostor, &camera);
        let (mut grown, mut area) = (0i64, 0i64);
        for (&a, &b) in shown.object.iter().zip(&exact.object) {
            grown += i64::from(a == 0) - i64::from(b == 0);
            area += i64::from(b == 0);
        }
        let outline = 2.0 * (std::f64::consts::PI * area as f64).sqrt();
        let psnr = |frame| object_psnr(frame, &reference, 0).expect("the sphere shows");
        (grown as f64 / outline, psnr(&shown) - psnr(&exact))
    };
    let (growth_16, gap_16) = measure(DepthBits::Sixteen);
    let (growth_8, gap_8) = measure(DepthBits::Eight);
    eprintln!("16 bits: {growth_16:.3} px, {gap_16:+.2} dB; 8 bits: {growth_8:.3} px, {gap_8:+.2} dB");
    assert!(
        growth_16.abs() < 0.15,
        "16 bits: grown by {growth_16:.3} px on average"
    );
    assert!(gap_16 > 0.0, "16 bits: {gap_16:+.2} dB against geometry");
    // (The check tells: with 8 bits the same frame loses.)
    assert!(gap_16 > gap_8 + 1.5, "8 bits: {gap_8:+.2} dB, 16: {gap_16:+.2}");
}

/// A closed surface shows no back face: the knot's impostor, drawn with only its front
/// faces, leaves out the texels its texture's eye saw that this eye sees from behind —
/// which, drawn, landed past the silhouette as fringes (the pixels only the impostor
/// covers) and showed surfaces turned away from the eye.
#[test]
fn a_closed_surface_shows_no_back_face() {
    use relief_render::gbuffer::GBuffer;
    use relief_render::impostor::Faces;
    use relief_render::raster::rasterize;
    use relief_render::warp::{Variant, display};

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "knot", 3.0).expect("solo");
    assert!(solo.scene.objects[0].is_closed(), "the knot is a closed tube");
    let size = 256;
    let eye = solo.eye(12.0);
    let camera = solo.camera(eye, size).expect("orbit camera");
    let texture = solo.bake(solo.eye(0.0), 256, DepthBits::Eight).expect("bake");
    let mut exact = GBuffer::new(size, size);
    rasterize(&[(0, &solo.scene.objects[0])], &camera, 0.01, &mut exact);
    let count = |faces: Faces| {
        let impostor = Impostor::new(texture.clone()).with_faces(faces);
        let mut shown = GBuffer::new(size, size);
        display(Variant::Interleaved, &impostor, 0, &camera, &mut shown).expect("display");
        let (mut fringe, mut turned_away) = (0, 0);
        for y in 0..size {
            for x in 0..size {
                let pixel = shown.get(x, y);
                if !pixel.is_covered() {
                    continue;
                }
                fringe += usize::from(!exact.get(x, y).is_covered());
                let ray = camera.ray(x as f32 + 0.5, y as f32 + 0.5);
                turned_away += usize::from(pixel.normal.dot(ray) > 0.05 * ray.length());
            }
        }
        (fringe, turned_away)
    };
    let (both, front) = (count(Faces::Both), count(Faces::Front));
    eprintln!("both faces: {both:?} (fringe, turned away); front only: {front:?}");
    assert!(
        front.1 * 10 <= both.1 && front.1 <= 20,
        "turned away: {front:?} vs {both:?}"
    );
    assert!(front.0 < both.0, "fringe: {front:?} vs {both:?}");
}

/// A perspective texture keeps the occlusion-compatible order wherever the eye goes:
/// nearer its plane than its centre (texels move towards the epipole), as far (the
/// epipole at infinity: a translation), and farther (texels move away from the
/// epipole, visited from it outwards). Each pixel drawn holds the surface nearest the
/// eye among the texels landing there — checked against every texel's surface point
/// projected to the screen and depth-tested, a brute-force splat — within a tenth of
/// the texture's depth range for interpolation (the tubes lie further apart): the wrong
/// order puts the knot's far tube over its near one (measured, visiting the farther
/// eye's halves towards the epipole: 29 of 4,032 pixels; in order: 2).
#[test]
fn a_perspective_texture_shows_its_nearest_surfaces_from_any_eye() {
    use glam::Vec3;
    use relief_render::gbuffer::GBuffer;
    use relief_render::warp::Prewarped;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "knot", 3.0).expect("solo");
    let source = solo.eye(0.0);
    let texture = solo
        .bake_in(source, 128, DepthBits::Eight, SourceProjection::Perspective)
        .expect("bake");
    let impostor = Impostor::new(texture.clone());
    let towards = solo.scene.objects[0].local_bounds.center() - source;
    let side = towards.cross(Vec3::Y).normalize() * towards.length();
    let size = 192;
    let tolerance = 0.1 * (texture.camera.depth_far - texture.camera.depth_near);
    for (label, eye, outward) in [
        ("nearer", source + towards * 0.15 + side * 0.05, false),
        ("beside", source + side * 0.08, false),
        ("farther", source - towards * 0.3 + side * 0.45, true),
    ] {
        let camera = solo.camera(eye, size).expect("camera");
        assert_eq!(
            WarpParams::new(&texture, eye).expect("warp").outward,
            outward,
            "{label}"
        );
        let mut gbuffer = GBuffer::new(size, size);
        Prewarped::new(Variant::Interleaved, &impostor, &camera)
            .expect("pre-warp")
            .draw(&impostor, 0, &camera, &mut gbuffer);
        let mut nearest = vec![f32::INFINITY; (size * size) as usize];
        for j in 0..texture.camera.height {
            for i in 0..texture.camera.width {
                let Some(point) = texture.world_point(i, j) else {
                    continue;
                };
                let view = camera.to_view(point);
                let (x, y) = camera.view_to_pixel(view);
                if view.z > 0.0 && (0.0..size as f32).contains(&x) && (0.0..size as f32).contains(&y) {
                    let k = y as usize * size as usize + x as usize;
                    nearest[k] = nearest[k].min(view.z);
                }
            }
        }
        let (mut shown, mut behind) = (0, 0);
        for (k, &depth) in gbuffer.depths().iter().enumerate() {
            let x = (k % size as usize) as u32;
            if gbuffer.get(x, (k / size as usize) as u32).is_covered() && nearest[k].is_finite() {
                shown += 1;
                behind += usize::from(depth > nearest[k] + tolerance);
            }
        }
        eprintln!("{label}: {behind} of {shown} pixels show a surface behind the nearest");
        assert!(shown > 3_000, "{label}: {shown} pixels");
        assert!(behind * 500 < shown, "{label}: {behind} of {shown} behind");
    }
}

/// A perspective texture holds what its eye sees: the tree at the texture's own eye,
/// over its own pixels against the anti-aliased reference, within 3 dB of exact
/// geometry drawn with one sample a pixel — where an orthographic texture, whose
/// parallel rays graze the leaves under the crown edge-on, misses them and scores far
/// lower (measured on a 256² frame: 22.8 dB, orthographic 18.9, geometry 24.1).
#[test]
fn a_perspective_texture_shows_the_leaves_parallel_rays_miss() {
    use relief_lab::image_error::object_psnr;
    use relief_render::gbuffer::GBuffer;
    use relief_render::impostor::Faces;
    use relief_render::pyramid::MAX_TEXEL_PIXELS;
    use relief_render::raster::rasterize;
    use relief_render::validity::schaufler::resolution_for;
    use relief_render::warp::{Variant, display};
    use relief_trace::ANTIALIASED_SAMPLES;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "tree", 1.5).expect("solo");
    let tree = &solo.scene.objects[0];
    let size = 256;
    let eye = solo.eye(0.0);
    let camera = solo.camera(eye, size).expect("orbit camera");
    let reference = solo.reference(&camera, ANTIALIASED_SAMPLES);
    let mut exact = GBuffer::new(size, size);
    rasterize(&[(0, tree)], &camera, 0.01, &mut exact);
    let geometry_db = object_psnr(&exact.shade(&solo.scene, &camera), &reference, 0).expect("the tree");
    let shown_db = |projection| {
        let edge =
            resolution_for(&tree.local_bounds, eye, projection, &camera, MAX_TEXEL_PIXELS).expect("edge");
        let texture = solo
            .bake_in(eye, edge, DepthBits::Eight, projection)
            .expect("bake");
        let impostor = Impostor::new(texture).with_faces(Faces::of(tree));
        let mut shown = GBuffer::new(size, size);
        display(Variant::Interleaved, &impostor, 0, &camera, &mut shown).expect("display");
        object_psnr(&shown.shade(&solo.scene, &camera), &reference, 0).expect("the tree")
    };
    let (perspective_db, orthographic_db) = (
        shown_db(SourceProjection::Perspective),
        shown_db(SourceProjection::Orthographic),
    );
    let measured = format!(
        "perspective {perspective_db:.2} dB, orthographic {orthographic_db:.2}, geometry {geometry_db:.2}"
    );
    eprintln!("{measured}");
    assert!(perspective_db > geometry_db - 3.0, "{measured}");
    assert!(orthographic_db < perspective_db - 3.0, "{measured}");
    // The forward and inverse methods, the thesis's, refuse a perspective texture.
    let texture = solo
        .bake_in(eye, 32, DepthBits::Eight, SourceProjection::Perspective)
        .expect("bake");
    for method in [Method::ForwardPullPush, Method::Inverse(64)] {
        let refused = relief_lab::methods::prepare(method, &Impostor::new(texture.clone()), &camera);
        assert!(
            matches!(
                refused,
                Err(relief_lab::methods::DisplayError::NeedsOrthographic { .. })
            ),
            "{method:?}"
        );
    }
}

/// The band a texture alone leaves unshown past its rim, predicted from the rim's
/// curvature ([`Rim::band`](relief_render::validity::rim::Rim::band)), is the band
/// the warp leaves: the sphere's texture shown from eyes turned 10–30° round it, row by
/// row across the sphere's middle, loses up to that many pixels of outline on the side
/// the eye turned to (measured against the exact outline) and nothing on the other.
#[test]
fn the_band_past_the_rim_is_what_the_warp_leaves_empty() {
    use relief_render::impostor::Faces;
    use relief_render::validity::rim::Rim;

    let scene = Scene::load("default").expect("default scene");
    let solo = Solo::new(&scene, "sphere", 3.0).expect("solo");
    let centre = solo.scene.objects[0].local_bounds.center();
    let size = 256;
    let texture = solo.bake(solo.eye(0.0), 256, DepthBits::Eight).expect("bake");
    let rim = Rim::find(&texture);
    let impostor = Impostor::new(texture.clone()).with_faces(Faces::Front);
    for degrees in [10.0, 20.0, 30.0] {
        let eye = solo.eye(degrees);
        let camera = solo.camera(eye, size).expect("orbit camera");
        let focal = camera.focal_pixels();
        let predicted = rim.band(&texture, centre, eye) * focal / eye.distance(centre);
        let (shown, exact) = impostor_and_geometry(&solo, &impostor, &camera);
        // Each row's outline, left and right (the first and last pixel of the sphere).
        let ends = |frame: &relief_core::frame::Frame, y: u32| {
            let row = &frame.object[(y * size) as usize..((y + 1) * size) as usize];
            let first = row.iter().position(|&o| o == 0)?;
            let last = row.iter().rposition(|&o| o == 0)?;
            Some((first as f32, last as f32))
        };
        let rows: Vec<u32> = (0..size).filter(|&y| ends(&exact, y).is_some()).collect();
        let middle = &rows[rows.len() / 3..2 * rows.len() / 3];
        let (mut left, mut right) = (0.0, 0.0);
        for &y in middle {
            let (Some(e), Some(s)) = (ends(&exact, y), ends(&shown, y)) else {
                panic!("row {y} of the sphere is not drawn");
            };
            left += s.0 - e.0;
            right += e.1 - s.1;
        }
        let (left, right) = (left / middle.len() as f32, right / middle.len() as f32);
        eprintln!("{degrees}°: band predicted {predicted:.2} px; left lost {left:.2}, right {right:.2}");
        let (lost, kept) = if left > right {
            (left, right)
        } else {
            (right, left)
        };
        // The warp runs each row's surface on half a span past its last texel, which
        // fills part of the band, unevenly from row to row (measured: 0.1, 1.1 and 4.3
        // px of 0.9, 3.4 and 7.5): the band bounds what is lost, and is much of it.
        assert!(
            lost <= predicted + 0.3 && lost >= 0.4 * predicted - 0.6,
            "{degrees}°: {lost:.2} px lost where {predicted:.2} were predicted"
        );
        assert!(
            kept.abs() < 0.6,
            "{degrees}°: {kept:.2} px lost on the side turned from"
        );
    }
}

/// `solo`'s object from `camera`: `impostor` drawn by the interleaved pre-warp, and the
/// exact geometry (one sample a pixel), both shaded.
fn impostor_and_geometry(
    solo: &Solo,
    impostor: &Impostor,
    camera: &relief_core::camera::Camera,
) -> (relief_core::frame::Frame, relief_core::frame::Frame) {
    use relief_render::gbuffer::GBuffer;
    use relief_render::raster::rasterize;
    use relief_render::warp::{Variant, display};

    let mut shown = GBuffer::new(camera.width, camera.height);
    display(Variant::Interleaved, impostor, 0, camera, &mut shown).expect("display");
    let mut exact = GBuffer::new(camera.width, camera.height);
    rasterize(&[(0, &solo.scene.objects[0])], camera, 0.01, &mut exact);
    (shown.shade(&solo.scene, camera), exact.shade(&solo.scene, camera))
}
