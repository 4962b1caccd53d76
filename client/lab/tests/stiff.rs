//! Stiff and extreme cases: every method returns a finite image or a clear "needs
//! regeneration / geometry" answer — no NaN or infinity in any buffer, no panic.

use glam::Vec3;

use relief_core::camera::Camera;
use relief_core::generators::Generator;
use relief_core::mesh::{Material, Mesh};
use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera, SourceProjection};
use relief_core::scene::{Scene, SceneObject, default_lighting};
use relief_core::shading::Specular;
use relief_lab::methods::{DisplayError, Method, display};
use relief_render::gbuffer::GBuffer;
use relief_render::impostor::Impostor;
use relief_render::warp::WarpError;
use relief_render::warp::params::WarpParams;
use relief_render::warp::prewarp::{Variant, prewarp};
use relief_render::warp::sprite::Sprite;
use relief_trace::bake;
use relief_trace::tracer::ObjectTracer;

fn scene_of(mesh: Mesh) -> Scene {
    let object = SceneObject::new("thing", mesh, glam::DVec3::ZERO, Specular::default());
    let mut scene = Scene {
        name: "stiff".into(),
        objects: vec![object],
        lighting: default_lighting(),
        background: Vec3::splat(0.5),
        fov_y_degrees: 50.0,
        path: Default::default(),
    };
    scene.path = scene.default_path();
    scene
}

fn sphere(scale: f32) -> Mesh {
    Generator::Sphere { subdivisions: 3 }
        .build()
        .transformed(glam::Affine3A::from_scale(Vec3::splat(scale)))
}

/// Shows `texture` with every method from `eye` (looking at `target`) and checks the
/// buffers. Returns how many methods drew something, and how many refused with a
/// reason.
fn check_all(scene: &Scene, texture: ReliefTexture, eye: Vec3, target: Vec3, what: &str) -> (usize, usize) {
    let up = if (target - eye).normalize_or_zero().dot(Vec3::Y).abs() > 0.99 {
        Vec3::Z
    } else {
        Vec3::Y
    };
    let camera = Camera::look_at(eye, target, up, 50.0, 96, 72).expect("test camera");
    let impostor = Impostor::new(texture);
    // The pre-warped images themselves hold only finite values.
    if let Ok(params) = WarpParams::new(&impostor.texture, eye) {
        assert!(
            params
                .add_u
                .iter()
                .chain(&params.add_v)
                .chain(&params.scale)
                .all(|x| x.is_finite())
        );
        for variant in Variant::ALL {
            let image = prewarp(&impostor, &params, variant);
            assert!(
                image.texels.iter().all(|t| t.depth.is_finite()),
                "{what}, {variant:?}: non-finite pre-warped depth"
            );
        }
    }
    let (mut drew, mut refused) = (0, 0);
    for method in Method::ALL {
        let mut gbuffer = GBuffer::new(camera.width, camera.height);
        match display(method, &impostor, 0, &camera, &mut gbuffer) {
            Ok(()) => {}
            Err(
                DisplayError::Warp(WarpError::EyeInPlane(_))
                | DisplayError::NeedsPreviousFrame
                | DisplayError::FarSide { .. }
                | DisplayError::TexelsTooLarge { .. },
            ) => refused += 1,
            Err(e) => panic!("{what}, {method}: unexpected error {e}"),
        }
        // (The other planes are integers: only depth can hold NaN or infinity.)
        for &depth in gbuffer.depths() {
            assert!(
                depth.is_finite() && depth > 0.0,
                "{what}, {method}: depth {depth}"
            );
        }
        drew += (gbuffer.covered() > 0 || gbuffer.fragments_of(0).next().is_some()) as usize;
        let frame = gbuffer.shade(scene, &camera);
        assert_eq!(frame.color.len(), 96 * 72);
        // `sprite` redraws a previous frame's impostor: this one's, captured and drawn
        // again, is the same pixels, as finite.
        if let Some(sprite) = Sprite::capture(&gbuffer, 0) {
            let mut again = GBuffer::new(camera.width, camera.height);
            sprite.draw(&mut again);
            for (x, y) in (0..camera.height).flat_map(|y| (0..camera.width).map(move |x| (x, y))) {
                assert_eq!(
                    again.stored(x, y),
                    gbuffer.stored(x, y),
                    "{what}, sprite of {method}"
                );
            }
        }
    }
    (drew, refused)
}

fn baked(scene: &Scene, eye: Vec3, size: u32, bits: DepthBits) -> ReliefTexture {
    bake(
        &ObjectTracer::new(&scene.objects[0]),
        eye,
        size,
        bits,
        SourceProjection::Orthographic,
    )
    .expect("bake")
}

#[test]
fn eye_in_near_and_behind_the_texture_plane() {
    let scene = scene_of(sphere(1.0));
    let source = Vec3::new(0.0, 0.0, 5.0);
    let texture = baked(&scene, source, 64, DepthBits::Eight);
    let c = texture.camera;
    let in_plane = c.plane_centre() + c.a.normalize() * 3.0;
    // In the plane (72° round the sphere from the texture's eye): the four pre-warps
    // refuse (the eye in the plane) and the sprite (no previous frame); the forward
    // and inverse methods, which need no plane, draw.
    let outcome = check_all(
        &scene,
        texture.clone(),
        in_plane + Vec3::Y * 1e-3,
        Vec3::ZERO,
        "in plane",
    );
    assert_eq!(outcome, (6, 5), "in plane: (drew, refused)");
    // A hair in front of it (k3 huge) and behind it.
    check_all(
        &scene,
        texture.clone(),
        in_plane - c.f * 1e-5,
        Vec3::ZERO,
        "near plane",
    );
    check_all(
        &scene,
        texture.clone(),
        in_plane + c.f * 0.5,
        Vec3::ZERO,
        "behind plane",
    );
    let params = relief_render::warp::params::WarpParams::new(&texture, in_plane);
    assert!(matches!(params, Err(WarpError::EyeInPlane(_))), "{params:?}");
}

#[test]
fn epipole_far_outside_and_inside_the_image_and_grazing_views() {
    let scene = scene_of(sphere(1.0));
    let texture = baked(&scene, Vec3::new(0.0, 0.3, 6.0), 64, DepthBits::Eight);
    // Pure sideways motion, far away: the epipole runs off towards infinity.
    check_all(
        &scene,
        texture.clone(),
        Vec3::new(4000.0, 0.3, 6.0),
        Vec3::ZERO,
        "sideways",
    );
    // Straight on: epipole inside the image.
    assert!(
        check_all(
            &scene,
            texture.clone(),
            Vec3::new(0.1, 0.2, 4.0),
            Vec3::ZERO,
            "head-on"
        )
        .0 >= 8
    );
    // Grazing: 89.5° away from the source direction.
    let grazing = Vec3::new(
        6.0 * 89.5f32.to_radians().sin(),
        0.0,
        6.0 * 89.5f32.to_radians().cos(),
    );
    check_all(&scene, texture.clone(), grazing, Vec3::ZERO, "grazing");
    // From the far side (120° round): no method draws the texture's side of the sphere
    // as if it were this one; each refuses with its reason.
    let far = Vec3::new(
        6.0 * 120f32.to_radians().sin(),
        0.3,
        6.0 * 120f32.to_radians().cos(),
    );
    let outcome = check_all(&scene, texture, far, Vec3::ZERO, "far side");
    assert_eq!(outcome, (0, Method::ALL.len()), "far side: (drew, refused)");
}

#[test]
fn eye_at_the_bounds_edge_and_inside() {
    let scene = scene_of(sphere(1.0));
    let texture = baked(&scene, Vec3::new(0.0, 0.0, 5.0), 64, DepthBits::Eight);
    // At a corner of the bounds, then inside them.
    check_all(
        &scene,
        texture.clone(),
        Vec3::splat(1.0001),
        Vec3::ZERO + Vec3::X * 1e-3,
        "corner",
    );
    check_all(
        &scene,
        texture.clone(),
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
        "inside",
    );
    // Baking from inside is refused with the reason.
    let inside = bake(
        &ObjectTracer::new(&scene.objects[0]),
        Vec3::new(0.0, 0.0, 0.5),
        16,
        DepthBits::Eight,
        SourceProjection::Orthographic,
    );
    assert!(inside.unwrap_err().to_string().contains("geometry"));
}

#[test]
fn extreme_scales_and_distances() {
    for size in [1e-3f32, 1e4] {
        let scene = scene_of(sphere(size * 0.5));
        for distance in [2.0 * size, 1e3 * size, 1e6 * size] {
            let eye = Vec3::new(0.2, 0.3, 1.0).normalize() * distance;
            let texture = baked(&scene, eye, 32, DepthBits::Sixteen);
            let turned = glam::Quat::from_rotation_y(0.1) * eye;
            check_all(
                &scene,
                texture,
                turned,
                Vec3::ZERO,
                &format!("size {size} at {distance}"),
            );
        }
        // Near range the impostor is visible and drawn by the warps.
        let eye = Vec3::new(0.0, 0.0, 3.0 * size);
        let texture = baked(&scene, eye, 32, DepthBits::Eight);
        assert!(check_all(&scene, texture, eye, Vec3::ZERO, &format!("size {size} near")).0 >= 8);
    }
}

#[test]
fn eight_bit_depth_on_a_very_deep_object() {
    // Two small squares 1000 m apart along the view: one depth level spans ~4 m.
    let square = |z: f32| {
        Generator::Plane {
            size: 1.0,
            divisions: 2,
        }
        .build()
        .transformed(glam::Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            Vec3::new(0.0, 0.0, z),
        ))
    };
    let mut mesh = square(0.0);
    mesh.append(square(-1000.0)).unwrap();
    let scene = scene_of(mesh);
    let texture = baked(&scene, Vec3::new(0.0, 0.0, 5.0), 64, DepthBits::Eight);
    assert!(texture.camera.depth_quantum(DepthBits::Eight) > 3.0);
    for eye in [
        Vec3::new(0.0, 0.0, 5.0),
        Vec3::new(2.0, 1.0, 4.0),
        Vec3::new(300.0, 0.0, 5.0),
    ] {
        check_all(&scene, texture.clone(), eye, Vec3::new(0.0, 0.0, -500.0), "deep");
    }
}

#[test]
fn empty_and_one_texel_textures() {
    let scene = scene_of(sphere(1.0));
    let bounds = scene.objects[0].local_bounds;
    let eye = Vec3::new(0.0, 0.0, 5.0);
    let empty = ReliefTexture::empty(
        SourceCamera::facing(eye, &bounds, 16, 16, SourceProjection::Orthographic).unwrap(),
        DepthBits::Eight,
        eye,
    );
    assert_eq!(check_all(&scene, empty, eye, Vec3::ZERO, "empty").0, 0);
    let one = baked(&scene, eye, 1, DepthBits::Eight);
    assert_eq!(one.covered_texels(), 1);
    // One texel across 30-odd pixels: the forward methods (three) refuse to draw a dot
    // for the sphere, as does the sprite.
    let (_, refused) = check_all(&scene, one.clone(), eye, Vec3::ZERO, "one texel");
    assert!(refused >= 4, "one texel: {refused} refused");
    check_all(
        &scene,
        one,
        Vec3::new(3.0, 0.0, 4.0),
        Vec3::ZERO,
        "one texel, turned",
    );
    // A mesh with no material-less surprises: a single triangle.
    let tri = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        triangles: vec![[0, 1, 2]],
        materials: vec![Material::default()],
        ..Default::default()
    };
    let scene = scene_of(tri);
    let texture = baked(&scene, Vec3::new(0.3, 0.3, 2.0), 8, DepthBits::Eight);
    check_all(
        &scene,
        texture,
        Vec3::new(0.6, 0.1, 2.0),
        Vec3::new(0.3, 0.3, 0.0),
        "flat triangle",
    );
}

/// A knot over a ground plane, at the world's origin and moved 10⁶ m out along x and
/// z (where an `f32` steps by 6 cm), seen from the same place relative to it: the same
/// depth levels baked, bit for bit, and the same frames — as impostor and as geometry
/// — within 0.2 dB of their ray-traced references and of each other.
#[test]
fn an_object_a_million_metres_out_draws_as_at_the_origin() {
    use glam::DVec3;
    use relief_lab::frame_plan::FramePlan;
    use relief_lab::image_error::compare;
    use relief_render::geometry::render_geometry;
    use relief_trace::{SceneTracer, render_reference};
    let at = |offset: DVec3| {
        let text = format!(
            "[[objects]]\nname = \"ground\"\ngenerator = {{ kind = \"plane\", size = 8.0, divisions = 1 }}\n\
             translate = [{}, {}, {}]\n\
             [[objects]]\nname = \"knot\"\n\
             generator = {{ kind = \"knot\", p = 2, q = 3, segments = 240, sides = 16, tube_radius = 0.28 }}\n\
             translate = [{}, {}, {}]\n",
            offset.x,
            offset.y,
            offset.z,
            offset.x,
            offset.y + 1.3,
            offset.z,
        );
        let scene = relief_core::scene::Scene::parse(&text).expect("scene");
        let eye = offset + DVec3::new(2.1, 2.3, 3.7);
        let camera = Camera::look_at(eye, offset + DVec3::new(0.0, 1.1, 0.0), Vec3::Y, 50.0, 240, 160)
            .expect("camera");
        let plan = FramePlan::bake(&scene, &camera, 4.0, DepthBits::Sixteen);
        assert_eq!(plan.impostors.len(), 1, "the knot is an impostor");
        let depth = plan.impostors[0].pyramid.levels[0].texture.depth.clone();
        let mut gbuffer = GBuffer::new(camera.width, camera.height);
        let (impostor, _) = plan.render(&scene, &camera, Method::Interleaved, &mut gbuffer);
        let geometry = render_geometry(&scene, &camera, &mut gbuffer);
        let reference = render_reference(&SceneTracer::new(&scene), &camera, 1);
        let knot = Some(1);
        let psnr = |frame| compare(frame, &reference, knot).psnr_whole_db;
        (depth, impostor.clone(), psnr(&impostor), psnr(&geometry))
    };
    let (depth0, frame0, impostor0, geometry0) = at(DVec3::ZERO);
    let (depth, frame, impostor, geometry) = at(DVec3::new(1e6, 0.0, -1e6));
    let levels_off = depth0.iter().zip(&depth).filter(|(a, b)| a != b).count();
    assert_eq!(levels_off, 0, "depth levels that differ, of {}", depth.len());
    assert!(
        impostor0 > 20.0 && geometry0 > 40.0,
        "{impostor0} dB, {geometry0} dB"
    );
    assert!(
        (impostor - impostor0).abs() <= 0.2,
        "impostor {impostor} dB, at the origin {impostor0}"
    );
    assert!(
        (geometry - geometry0).abs() <= 0.2,
        "geometry {geometry} dB, at the origin {geometry0}"
    );
    let same = compare(&frame, &frame0, None);
    assert!(
        same.psnr_whole_db > 60.0,
        "the two impostor frames differ: {same:?}"
    );
}
