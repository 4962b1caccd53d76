//! The interleaved pre-warp eight texels at a time, where the surface is smooth.
//!
//! Seen a few degrees from its eye, a texture's texels land about one pre-warped pixel
//! apart: most spans between connected neighbours hold one pixel centre, or none, and
//! the column each lands in continues a run there. Turned further, the surfaces the
//! view turns towards stretch, and spans of two centres come often. Eight spans of up
//! to two centres (eight samples in all) are computed as one vector ([`row_block`],
//! module `rows`): where each lands, which centres it holds, the interpolated samples
//! there. Their samples fall in consecutive columns, and those columns take their next
//! sample as one vector too, a span of up to two centres each
//! ([`Columns::take_block`], module `columns`). Lanes that meet anything else — a run's
//! end, a crack, a span of three centres or more, a column starting a run — go through
//! the scalar code: a row's in the visit's order, a column's after the block's vector
//! step (each lane is a column of its own, so no write of one comes between another's).
//!
//! # Same pixels
//!
//! Every lane computes exactly what the scalar pass computes, with the same operations
//! in the same order (Rust never fuses a multiply and an add on its own), so the image
//! is bit for bit the one the scalar pass makes: the tests compare the two.
//!
//! # Layout
//!
//! - `vectors`: the eight-lane loads, masks and gathers, and the attribute blend.
//! - `rows`: a row's samples ([`RowSamples`], [`sample_eight`]) and its blocks of spans
//!   ([`row_block`]).
//! - `columns`: the column state ([`Columns`]) and its blocks of steps.

mod columns;
mod rows;
mod vectors;

pub(in crate::warp::prewarp) use columns::Columns;
pub(in crate::warp::prewarp) use rows::{Emitted, RowSamples, row_block, sample_eight};
pub(crate) use vectors::{field, lerp_attributes};

/// Lanes per block.
pub(in crate::warp::prewarp) const LANES: usize = 8;

/// Coordinates up to this size convert exactly between `f32` and integers, with room
/// for the half-pixel offsets; beyond it (an epipole far off) the scalar code runs.
const EXACT: f32 = 4_000_000.0;

/// [`RowSamples::flags`]: the texel holds a surface that shows from the eye.
pub(in crate::warp::prewarp) const VALID: u8 = 1;
/// The texel is connected to its right neighbour.
pub(in crate::warp::prewarp) const RIGHT_LINK: u8 = 2;
/// The texel is connected to the one below.
pub(in crate::warp::prewarp) const DOWN_LINK: u8 = 4;
/// Lanes `0..n` set.
#[inline(always)]
pub(in crate::warp::prewarp) fn first(n: u32) -> u32 {
    (1u32 << n) - 1
}

#[cfg(test)]
pub(crate) mod tests {
    use std::cell::Cell;

    use glam::{Quat, Vec3};
    use relief_core::camera::Camera;
    use relief_core::relief::{DepthBits, SourceProjection};
    use relief_core::scene::Scene;
    use relief_trace::{bake, tracer::ObjectTracer};

    use super::super::{PTexel, PlaneWindow, PrewarpImage, Variant, prewarp_with};
    use crate::gbuffer::GBuffer;
    use crate::impostor::{Faces, Impostor, SurfaceExtent};
    use crate::warp::display;
    use crate::warp::params::WarpParams;

    thread_local! {
        /// Texels the row blocks took on this thread, visiting leftwards and rightwards.
        pub(in super::super) static TAKEN_IN_ROWS: [Cell<usize>; 2] = const { [Cell::new(0), Cell::new(0)] };
        /// Spans of two pixel centres the row blocks and the column blocks took.
        pub(in super::super) static PAIRS_TAKEN: [Cell<usize>; 2] = const { [Cell::new(0), Cell::new(0)] };
        /// Samples the column blocks took, visiting upwards and downwards.
        pub(in super::super) static TAKEN_IN_COLUMNS: [Cell<usize>; 2] = const { [Cell::new(0), Cell::new(0)] };
    }

    /// An object of the default scene as these tests bake it: its tracer, its centre, and
    /// the textures' eye, three bounding radii off and a little above.
    pub(crate) fn baked_from(scene: &Scene, name: &str) -> (ObjectTracer, Vec3, Vec3) {
        let object = scene.object(name).expect("object");
        let centre = object.local_bounds.center();
        let radius = object.local_bounds.extent().length() * 0.5;
        let eye = centre + Vec3::new(0.0, 0.25, 1.0).normalize() * 3.0 * radius;
        (ObjectTracer::new(object), centre, eye)
    }

    /// Eyes turned every way about `centre` from the textures' `eye`, nearer and farther
    /// than it (so visited towards the epipole and outwards): yaw and pitch (degrees),
    /// the distance's factor, and the eye.
    fn turned_eyes(centre: Vec3, eye: Vec3) -> impl Iterator<Item = (f32, f32, f32, Vec3)> {
        let turns = [(-40.0f32, 0.0f32), (-5.0, 3.0), (4.0, -20.0), (25.0, 12.0)];
        turns.into_iter().flat_map(move |(yaw, pitch)| {
            [0.6f32, 1.0, 2.0].into_iter().map(move |distance| {
                let turn =
                    Quat::from_rotation_y(yaw.to_radians()) * Quat::from_rotation_x(pitch.to_radians());
                (yaw, pitch, distance, centre + turn * (eye - centre) * distance)
            })
        })
    }

    /// The image's placement, and each texel's depth bits and attribute bytes.
    fn bits(image: &PrewarpImage) -> Vec<u64> {
        let texels = image.texels.iter().flat_map(|t| {
            let [r, g, b] = t.attributes.albedo();
            let [x, y, z] = t.attributes.normal();
            [
                t.depth.to_bits().into(),
                u64::from_le_bytes([r, g, b, x, y, z, 0, 0]),
            ]
        });
        let placement = [
            image.u0 as u64,
            image.v0 as u64,
            image.width.into(),
            image.height.into(),
        ];
        placement.into_iter().chain(texels).collect()
    }

    /// Eight lanes at a time make the very image the scalar pass makes, bit for bit,
    /// and so does visiting each row whole rather than its occupied texels only:
    /// a self-occluding knot and a tree of leaves (cracks, runs of one texel), baked
    /// orthographic and perspective, 8- and 16-bit, all faces or the front ones, seen
    /// from eyes turned every way, nearer and farther than the texture's (so visited
    /// towards the epipole and outwards), whole and through a window. A good share of
    /// the texels go through the lanes (fails if they stop being used).
    #[test]
    fn eight_lanes_make_the_scalar_image() {
        let scene = Scene::load("default").expect("default scene");
        let (mut cases, mut visited, mut whole_visited) = (0, 0, 0);
        let counts = || {
            let read = |cells: &[Cell<usize>; 2]| [cells[0].get(), cells[1].get()];
            (TAKEN_IN_ROWS.with(read), TAKEN_IN_COLUMNS.with(read))
        };
        let (rows_before, columns_before) = counts();
        let pairs = || PAIRS_TAKEN.with(|n| [n[0].get(), n[1].get()]);
        let pairs_before = pairs();
        for name in ["knot", "tree"] {
            let (tracer, centre, eye) = baked_from(&scene, name);
            for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
                for depth_bits in [DepthBits::Eight, DepthBits::Sixteen] {
                    let texture = bake(&tracer, eye, 96, depth_bits, projection).expect("baked");
                    for faces in [Faces::Both, Faces::Front] {
                        let impostor = Impostor::new(texture.clone()).with_faces(faces);
                        // The same, visiting every texel of each row.
                        let whole_rows = Impostor {
                            occupied: vec![0..texture.camera.width as usize; texture.camera.height as usize],
                            ..impostor.clone()
                        };
                        for (yaw, pitch, distance, moved) in turned_eyes(centre, eye) {
                            let Ok(params) = WarpParams::new(&impostor.texture, moved) else {
                                continue;
                            };
                            let window = PlaneWindow {
                                u0: 30.0,
                                v0: -4.0,
                                u1: 70.0,
                                v1: 60.0,
                            };
                            for seen in [None, Some(&window)] {
                                let warp = |impostor: &Impostor, lanes| {
                                    prewarp_with(impostor, &params, Variant::Interleaved, seen, false, lanes)
                                };
                                let lanes = warp(&impostor, true);
                                let scalar = bits(&warp(&impostor, false));
                                let whole = warp(&whole_rows, false);
                                whole_visited += whole.visited;
                                assert!(
                                    scalar == bits(&whole),
                                    "occupied texels only: {name} {projection:?} {depth_bits:?} {faces:?} \
                                         yaw {yaw} pitch {pitch} ×{distance} window {}",
                                    seen.is_some()
                                );
                                assert!(
                                    bits(&lanes) == scalar,
                                    "{name} {projection:?} {depth_bits:?} {faces:?} yaw {yaw} pitch {pitch} \
                                         ×{distance} window {}",
                                    seen.is_some()
                                );
                                cases += 1;
                                visited += lanes.visited;
                            }
                        }
                    }
                }
            }
        }
        let (rows, columns) = counts();
        let took = |after: [usize; 2], before: [usize; 2]| [after[0] - before[0], after[1] - before[1]];
        let (rows, columns) = (took(rows, rows_before), took(columns, columns_before));
        assert!(cases >= 150, "{cases} cases");
        // The rows' occupied texels leave out a good share of the whole rows (when
        // written: 1.43 M of 2.73 M texels visited).
        assert!(
            visited * 4 < whole_visited * 3,
            "{visited} texels visited, {whole_visited} in whole rows"
        );
        // Spans of two centres go through the lanes too, in rows and in columns (fails
        // if they stop being taken).
        let pairs_after = pairs();
        for (what, (after, before)) in ["rows", "columns"]
            .iter()
            .zip(pairs_after.into_iter().zip(pairs_before))
        {
            assert!(after > before, "{what}: no span of two centres taken in lanes");
        }
        // Each way of visiting rows and columns takes its share in lanes (of every texel
        // visited, empty ones within rows included, when written: rows 27 and 30 %,
        // columns 18 and 19 %).
        for (what, taken) in [("rows", rows), ("columns", columns)] {
            for (way, n) in ["backwards", "forwards"].iter().zip(taken) {
                assert!(
                    n * 10 > visited,
                    "{what} visited {way}: {n} of {visited} texels in lanes"
                );
            }
        }
    }

    /// An image bounded by the texels holding surface (`Impostor::surface`) holds every
    /// pixel one bounded by the whole quad at every depth does, and the texture mapping
    /// draws the same frame from it: the knot and the tree, orthographic and
    /// perspective, from eyes turned every way, nearer and farther. And it is smaller
    /// (fails if the surface stops bounding it). (Where a surface meets its texture's
    /// edge, the image's edge, which the mapping draws by a rule of its own, must stay
    /// there: the lab's `texture_mapping_covers_a_full_texture_to_its_edges` shows such a
    /// texture; none of these does.)
    #[test]
    fn an_image_bounded_by_its_surface_loses_nothing() {
        let scene = Scene::load("default").expect("default scene");
        let (mut cases, mut tight_pixels, mut quad_pixels) = (0, 0, 0);
        for name in ["knot", "tree"] {
            let index = scene.objects.iter().position(|o| o.name == name).expect("index") as u32;
            let (tracer, centre, eye) = baked_from(&scene, name);
            for projection in [SourceProjection::Orthographic, SourceProjection::Perspective] {
                let texture = bake(&tracer, eye, 96, DepthBits::Sixteen, projection).expect("baked");
                let impostor = Impostor::new(texture.clone());
                let (w, h) = (texture.camera.width as usize, texture.camera.height as usize);
                for (yaw, pitch, distance, moved) in turned_eyes(centre, eye) {
                    let Ok(params) = WarpParams::new(&impostor.texture, moved) else {
                        continue;
                    };
                    let quad = Impostor {
                        surface: Some(SurfaceExtent {
                            columns: 0..w,
                            rows: 0..h,
                            entries: 0..=(params.scale.len() - 1) as u16,
                        }),
                        ..impostor.clone()
                    };
                    let warp = |impostor: &Impostor| {
                        prewarp_with(impostor, &params, Variant::Interleaved, None, false, true)
                    };
                    let (tight, whole) = (warp(&impostor), warp(&quad));
                    let case = format!("{name} {projection:?} yaw {yaw} pitch {pitch} ×{distance}");
                    for (k, pixel) in whole.texels.iter().enumerate() {
                        let (x, y) = (
                            (k % whole.width as usize) as i32,
                            (k / whole.width as usize) as i32,
                        );
                        let (u, v) = ((whole.u0 + x) as f32 + 0.5, (whole.v0 + y) as f32 + 0.5);
                        let held = tight.at(u, v).copied().unwrap_or(PTexel::EMPTY);
                        assert!(held == *pixel, "{case}: pixel ({u}, {v})");
                    }
                    // And the texture mapping draws the same frame from either: the same
                    // pixels covered, by the same objects, to the rounding of plane
                    // coordinates taken from another image origin (a blend's weight a
                    // 256th off: a level of albedo, an encoded normal's quantum; in the
                    // 46 cases when written, colours off by at most 1).
                    let camera = Camera::look_at(moved, centre, Vec3::Y, 50.0, 160, 120).expect("camera");
                    let drawn = |impostor: &Impostor| {
                        let mut frame = GBuffer::new(160, 120);
                        display(Variant::Interleaved, impostor, index, &camera, &mut frame).expect("shown");
                        let pixels: Vec<_> = (0..120).flat_map(|y| (0..160).map(move |x| (x, y))).collect();
                        let kept = pixels.iter().map(|&(x, y)| frame.get(x, y)).collect::<Vec<_>>();
                        (kept, frame.shade(&scene, &camera))
                    };
                    let ((kept, shaded), (quad_kept, quad_shaded)) = (drawn(&impostor), drawn(&quad));
                    for (p, q) in kept.iter().zip(&quad_kept) {
                        assert!(
                            p == q
                                || p.object == q.object
                                    && (0..3).all(|c| p.albedo[c].abs_diff(q.albedo[c]) <= 1)
                                    && (p.depth - q.depth).abs() <= 1e-4 * q.depth.abs().max(1.0)
                                    && p.normal.dot(q.normal) >= 0.999,
                            "{case}: {p:?} against {q:?}"
                        );
                    }
                    let off = (shaded.color.iter().zip(&quad_shaded.color))
                        .map(|(p, q)| (0..3).map(|c| p[c].abs_diff(q[c])).max().unwrap_or(0))
                        .max()
                        .unwrap_or(0);
                    assert!(off <= 2, "{case}: colours off by {off}");
                    tight_pixels += tight.texels.len();
                    quad_pixels += whole.texels.len();
                    cases += 1;
                }
            }
        }
        assert!(cases >= 20, "{cases} cases");
        assert!(
            tight_pixels * 10 < quad_pixels * 9,
            "{tight_pixels} pixels bounded by the surface, {quad_pixels} by the quad"
        );
    }
}
