//! The software rasterizer: triangles of scene objects into a [`GBuffer`].
//!
//! Perspective-correct and z-buffered, sampling pixel centres. Triangles crossing the
//! near plane are clipped in view space (`clip.rs`); the frame is split into bands of
//! [`BAND`] rows rasterized in parallel, each band seeing only the triangles that reach
//! it. Attributes are not interpolated here: each written pixel records the original
//! triangle's barycentric coordinates and asks the mesh for its albedo and shading
//! normal — the same functions the ray tracer uses.

mod clip;

use glam::Vec2;
use rayon::prelude::*;
use wide::f32x8;

use relief_core::camera::Camera;
use relief_core::scene::SceneObject;
use relief_core::shading::{LANES, set_lanes, to_rgb8};

use crate::gbuffer::{GBuffer, GPixel, Rows, Stored};

/// Rows per parallel band.
pub const BAND: usize = 16;

/// A triangle's box more than this many groups of [`LANES`] pixels wide is walked row
/// by row within the triangle's [`RowSpans`]; a narrower one tests its every group of
/// each row: a row's span costs about what two groups' tests do. (With spans for boxes
/// more than one group wide, the trees the forest's flight draws as geometry took
/// 27.2–27.6 ms a frame where they take 25.2–25.5, the same images: `RAYON_NUM_THREADS=1
/// relief bench raster --scene forest --as-client --size 1280x720`.)
const SPANNED_GROUPS: usize = 2;

/// A triangle in screen space: pixel positions, view depth, and for each corner its
/// barycentric position in the original mesh triangle (which differs after clipping).
#[derive(Debug, Clone, Copy)]
struct ScreenTriangle {
    /// Position in the `objects` slice given to [`rasterize`].
    slot: u32,
    triangle: u32,
    xy: [Vec2; 3],
    depth: [f32; 3],
    bary: [Vec2; 3],
    /// The pixels whose centres its bounding box holds ([`pixel_box`]), as `[x0, y0,
    /// x1, y1]`, inclusive: found as it is set up, read by every band it reaches.
    pixels: [u32; 4],
}

/// Draws `objects` (pairs of scene index and object) into `gbuffer` as seen by
/// `camera`, clipping at view depth `near`.
pub fn rasterize(objects: &[(u32, &SceneObject)], camera: &Camera, near: f32, gbuffer: &mut GBuffer) {
    let (w, h) = (gbuffer.width as usize, gbuffer.height as usize);
    if w == 0 || h == 0 {
        return;
    }
    let bands = h.div_ceil(BAND);
    // Set up and bin every triangle by the bands its bounding box touches.
    let mut triangles: Vec<ScreenTriangle> = Vec::new();
    let projection = camera.projection();
    for (slot, &(_, object)) in objects.iter().enumerate() {
        // An object wholly off screen costs nothing (its vertices would all be
        // projected before the triangle cull throws them out).
        // (In the object's frame: see `SceneObject`.)
        let camera = object.local_camera(camera);
        if !camera.may_see(&object.local_bounds) {
            continue;
        }
        // Each vertex projected once (a vertex is a corner of ~6 triangles); only the
        // triangles crossing the near plane are projected again, corner by corner. In
        // the world's metres: a scaled frame's view coordinates times its scale (the
        // same pixels, depths the frame's others compare with).
        let scale = object.depth_scale();
        let vertices: Vec<clip::Corner> = object
            .mesh
            .positions
            .par_iter()
            .map(|&p| clip::Corner::new(&projection, camera.to_view(p) * scale))
            .collect();
        let set_up: Vec<ScreenTriangle> = object
            .mesh
            .triangles
            .par_iter()
            .enumerate()
            .filter_map(|(t, corners)| {
                let v = corners.map(|i| vertices[i as usize]);
                // Most triangles of a detailed object fall between pixel centres: cull
                // those in front of the near plane before any more set-up.
                let culled =
                    v.iter().all(|c| c.view.z >= near) && pixel_box(v.map(|c| c.pixel), w, h).is_none();
                (!culled).then_some((t, v))
            })
            .flat_map_iter(|(t, v)| {
                clip::clip_and_project(&projection, near, v)
                    .into_iter()
                    .filter_map(move |(xy, depth, bary)| {
                        let (x0, y0, x1, y1) = pixel_box(xy, w, h)?;
                        Some(ScreenTriangle {
                            slot: slot as u32,
                            triangle: t as u32,
                            xy,
                            depth,
                            bary,
                            pixels: [x0, y0, x1, y1].map(|p| p as u32),
                        })
                    })
            })
            .collect();
        triangles.extend(set_up);
    }
    let bins: Vec<Vec<u32>> = triangles
        .par_iter()
        .enumerate()
        .fold(
            || vec![Vec::new(); bands],
            |mut bins: Vec<Vec<u32>>, (k, s)| {
                // (`pixels` is on screen: every band it names is one of `bands`.)
                let [_, first, _, last] = s.pixels.map(|p| p as usize);
                for bin in &mut bins[first / BAND..=last / BAND] {
                    bin.push(k as u32);
                }
                bins
            },
        )
        .reduce(
            || vec![Vec::new(); bands],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(b) {
                    x.extend(y);
                }
                a
            },
        );
    let height = gbuffer.height;
    gbuffer
        .bands(0, height, BAND)
        .into_par_iter()
        .zip(bins.par_iter())
        // (Band by band: an object covers few bands, which rayon's default halves
        // left mostly to one thread — the default tree took 1.75-1.83 ms a frame,
        // against 1.51-1.53 so.)
        .with_max_len(1)
        .for_each(|(mut rows, bin)| {
            for &k in bin {
                let s = &triangles[k as usize];
                let (index, object) = objects[s.slot as usize];
                draw(s, index, object, &mut rows, w);
            }
        });
}

/// Twice the signed area of `(p, q, r)`, computed with `p` and `q` in lexicographic
/// order so that the edge `q → p` gives exactly the negated value.
#[inline(always)]
fn edge(p: Vec2, q: Vec2, r: Vec2) -> f32 {
    OrderedEdge::new(p, q, 1.0).value_at(r)
}

/// Where a triangle's edges cross each row, set up once per triangle and band (each edge's
/// slope: a division, where a row then costs a multiply-add an edge — a leaf, thin
/// and tall, meets many rows for few pixels, and the divisions per row were the
/// tree's largest cost drawn as geometry).
#[derive(Clone, Copy)]
struct RowSpans {
    /// Per edge, where it crosses the rows; `None` for an edge parallel to them — all
    /// of a row or none, which the exact tests decide.
    edges: [Option<Crossing>; 3],
}

/// How many times `f32::EPSILON` of its size (see [`Crossing::margin`]) an edge's
/// crossing is widened by: the crossing and the exact test each round a few products
/// and differences (about 14 roundings between them at worst); more than twice that, so
/// no pixel the exact test accepts is ever outside its row's span (the span test passes
/// from 1).
const SPAN_ROUNDINGS: f32 = 32.0;

/// Where an edge `p → q` crosses the rows: at `x = p.x + (y − p.y)·slope`.
#[derive(Clone, Copy)]
struct Crossing {
    p: Vec2,
    /// `(q.x − p.x) / (q.y − p.y)`.
    slope: f32,
    /// The inside lies right of the crossing (it is the span's left end).
    left_end: bool,
    /// How far the crossing is widened, pixels: [`SPAN_ROUNDINGS`] roundings of the
    /// largest term the crossing or the exact test sums at a row of the triangle — its
    /// slope times the rows it spans, and the triangle's largest coordinate. An edge
    /// nearly parallel to the rows (a large `slope`, dx/dy) is widened most: there the
    /// exact test's rounding moves its zero furthest along the row. (A margin of whole
    /// pixels would leave a thin leaf a block of 8 pixels to test on most of its rows,
    /// where no centre lies inside.)
    margin: f32,
}

impl RowSpans {
    /// The edges of the triangle `corners`, oriented by `sign`.
    fn new(corners: [Vec2; 3], sign: f32) -> RowSpans {
        let largest = corners.iter().fold(0f32, |m, c| m.max(c.x.abs()).max(c.y.abs()));
        let rows = corners.iter().map(|c| c.y).fold(f32::NEG_INFINITY, f32::max)
            - corners.iter().map(|c| c.y).fold(f32::INFINITY, f32::min);
        let edges = [0, 1, 2].map(|k| {
            let (p, q) = (corners[(k + 1) % 3], corners[(k + 2) % 3]);
            let dy = q.y - p.y;
            // The inside of the edge p → q is where sign·E ≥ 0, E growing with x as −dy.
            (dy != 0.0).then(|| {
                let slope = (q.x - p.x) / dy;
                Crossing {
                    p,
                    slope,
                    left_end: sign * dy < 0.0,
                    margin: SPAN_ROUNDINGS * f32::EPSILON * (slope.abs() * (rows + 2.0) + largest + 1.0),
                }
            })
        });
        RowSpans { edges }
    }

    /// The pixels `x` of row centre `py` in `bounds` whose centres the triangle can
    /// cover: each edge bounds the row on one side where it crosses it. Widened against
    /// rounding — the per-pixel tests inside stay exact, so the shared-edge rule holds
    /// — it spares the tests of the bounding box's pixels outside the triangle (half of
    /// them for a large one). `None` when empty.
    #[inline]
    fn row(&self, py: f32, bounds: (usize, usize)) -> Option<(usize, usize)> {
        let (mut lo, mut hi) = (f32::NEG_INFINITY, f32::INFINITY);
        for &Crossing {
            p,
            slope,
            left_end,
            margin,
        } in self.edges.iter().flatten()
        {
            let crossing = p.x + (py - p.y) * slope;
            if left_end {
                lo = lo.max(crossing - margin);
            } else {
                hi = hi.min(crossing + margin);
            }
        }
        // (NaN bounds leave `max`/`min` unchanged: the whole box is tested.)
        let first = ((lo - 0.5).ceil().max(bounds.0 as f32) as usize).max(bounds.0);
        let last = ((hi - 0.5).floor().min(bounds.1 as f32) as usize).min(bounds.1);
        (first <= last).then_some((first, last))
    }
}

/// The pixels of the `w × h` screen whose centres (`k + 0.5`) the bounding box of the
/// triangle `xy` holds, as `(x0, y0, x1, y1)` inclusive — the pixels [`draw`] tests —
/// or `None` when there are none: then the triangle covers no pixel. (Most triangles
/// of a million-triangle object seen whole are smaller than a pixel, and most of those
/// fall between pixel centres.)
#[inline]
fn pixel_box(xy: [Vec2; 3], w: usize, h: usize) -> Option<(usize, usize, usize, usize)> {
    // (`min`/`max` skip NaN: test the corners.)
    if !xy.iter().all(|p| p.is_finite()) {
        return None;
    }
    let min = xy[0].min(xy[1]).min(xy[2]);
    let max = xy[0].max(xy[1]).max(xy[2]);
    let first = (min - 0.5).ceil().max(Vec2::ZERO);
    let last = (max - 0.5).floor().min(Vec2::new(w as f32 - 1.0, h as f32 - 1.0));
    (first.x <= last.x && first.y <= last.y).then_some((
        first.x as usize,
        first.y as usize,
        last.x as usize,
        last.y as usize,
    ))
}

/// Scan-converts one triangle into the band `rows` of the screen, `w` pixels wide.
fn draw(s: &ScreenTriangle, index: u32, object: &SceneObject, rows: &mut Rows, w: usize) {
    let (y0, rows_here) = (rows.y0() as usize, rows.rows());
    let [a, b, c] = s.xy;
    // Edge functions, each evaluated with its edge's endpoints in a fixed order so that
    // two triangles sharing an edge get exactly opposite values there: no pixel on a
    // shared edge is missed by both (watertight).
    let area = edge(b, c, a);
    if area == 0.0 || !area.is_finite() {
        return;
    }
    let sign = area.signum();
    let inv_area = 1.0 / area.abs();
    let [x_start, first_row, x_end, last_row] = s.pixels.map(|p| p as usize);
    // Its rows in this band.
    let (y_start, y_end) = (first_row.max(y0), last_row.min(y0 + rows_here - 1));
    let inv_depth = s.depth.map(|d| 1.0 / d);
    let mesh = &object.mesh;
    let tri = s.triangle as usize;
    // A triangle of one colour and one normal (the ground; flat-shaded meshes) needs no
    // interpolation of them per pixel.
    let uniform_albedo = mesh.uniform_albedo(tri).map(to_rgb8);
    let uniform_normal = mesh.uniform_normal(tri);
    let uniform = uniform_albedo
        .zip(uniform_normal)
        .map(|(albedo, normal)| Stored::new(index, albedo, normal));
    // The three edge functions, each with its endpoints in `edge`'s order, signed so
    // that the inside is ≥ 0; evaluated as `edge` does, eight pixels at a time.
    let edges = [(b, c), (c, a), (a, b)].map(|(p, q)| OrderedEdge::new(p, q, sign));
    let inv_area = f32x8::splat(inv_area);
    let inv_depth = inv_depth.map(f32x8::splat);
    let spans = (x_end - x_start >= SPANNED_GROUPS * LANES).then(|| RowSpans::new([a, b, c], sign));
    for y in y_start..=y_end {
        let py = y as f32 + 0.5;
        let span = match &spans {
            Some(spans) => spans.row(py, (x_start, x_end)),
            None => Some((x_start, x_end)),
        };
        let Some((x_first, x_last)) = span else {
            continue;
        };
        let row = edges.map(|e| e.row(py));
        let row_start = (y - y0) * w;
        for x in (x_first..=x_last).step_by(LANES) {
            let n = LANES.min(x_last + 1 - x);
            let px = f32x8::splat(x as f32) + PIXEL_CENTRES;
            // Screen-space barycentric weights of corners a, b, c.
            let [ea, eb, ec] = [0, 1, 2].map(|k| edges[k].at(row[k], px));
            let inside = ea.simd_ge(f32x8::ZERO) & eb.simd_ge(f32x8::ZERO) & ec.simd_ge(f32x8::ZERO);
            let inside = inside.to_bitmask() & ((1 << n) - 1);
            if inside == 0 {
                continue;
            }
            // Perspective correction: interpolate 1/depth, weight attributes by it.
            let pa = ea * inv_area * inv_depth[0];
            let pb = eb * inv_area * inv_depth[1];
            let pc = ec * inv_area * inv_depth[2];
            let sum = pa + pb + pc;
            let depth = f32x8::ONE / sum;
            if let Some(stored) = &uniform {
                rows.keep_nearer_stored_lanes(row_start + x, inside, depth, stored);
                continue;
            }
            let depth = depth.to_array();
            let (pa, pb, pc, sum) = (pa.to_array(), pb.to_array(), pc.to_array(), sum.to_array());
            for l in set_lanes(inside) {
                let i = row_start + x + l;
                // (`depth` is finite and positive: clipping keeps depths at or beyond
                // `near`; tested as "nearer" all the same, so a NaN would not pass.)
                let nearer = depth[l] < rows.depth(i);
                if !nearer {
                    continue;
                }
                // (Here one of the two is not uniform: the barycentrics are needed.)
                let bary = (s.bary[0] * pa[l] + s.bary[1] * pb[l] + s.bary[2] * pc[l]) / sum[l];
                rows.set(
                    i,
                    GPixel {
                        depth: depth[l],
                        object: index,
                        albedo: uniform_albedo.unwrap_or_else(|| to_rgb8(mesh.albedo(tri, bary.x, bary.y))),
                        normal: uniform_normal.unwrap_or_else(|| mesh.shading_normal(tri, bary.x, bary.y)),
                    },
                );
            }
        }
    }
}

/// `l + 0.5` in lane `l`: the centres of eight pixels from a row's `x`.
const PIXEL_CENTRES: f32x8 = f32x8::new([0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5]);

/// One edge function of a triangle, `sign · edge(p, q, r)`, set up once: the endpoints
/// in lexicographic order (so `q → p` gives exactly the negated values: shared edges
/// stay watertight), that order's sign and the triangle's orientation folded into one
/// factor. [`edge`] is one of these at one point.
#[derive(Clone, Copy)]
struct OrderedEdge {
    from: Vec2,
    step: Vec2,
    sign: f32,
}

impl OrderedEdge {
    fn new(p: Vec2, q: Vec2, sign: f32) -> OrderedEdge {
        if (p.x, p.y) < (q.x, q.y) {
            OrderedEdge {
                from: p,
                step: q - p,
                sign,
            }
        } else {
            OrderedEdge {
                from: q,
                step: p - q,
                sign: -sign,
            }
        }
    }

    /// The edge function at `r`.
    #[inline(always)]
    fn value_at(&self, r: Vec2) -> f32 {
        self.sign * (self.row(r.y) - self.step.y * (r.x - self.from.x))
    }

    /// The part of the edge function fixed along the row of centre `py`.
    #[inline(always)]
    fn row(&self, py: f32) -> f32 {
        self.step.x * (py - self.from.y)
    }

    /// [`OrderedEdge::value_at`] at pixel centres `px` of the row whose
    /// [`OrderedEdge::row`] term is `row`, with the same operations.
    #[inline(always)]
    fn at(&self, row: f32, px: f32x8) -> f32x8 {
        f32x8::splat(self.sign)
            * (f32x8::splat(row) - f32x8::splat(self.step.y) * (px - f32x8::splat(self.from.x)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pixel the exact edge tests accept lies in its row's span, for triangles
    /// of every size and orientation, on and far off screen; and for those where
    /// rounding decides: corners on pixel centres and on quarter pixels (edges through
    /// centres), slivers a thousandth of a pixel thin, and edges nearly parallel to the
    /// rows. (Without the crossings' margin, spans miss pixels here.)
    #[test]
    fn row_spans_hold_every_covered_pixel() {
        let (w, h) = (64usize, 48usize);
        let mut seed = 0x2545_f491_u32;
        let mut next = |scale: f32| {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            (seed as f32 / u32::MAX as f32 - 0.3) * scale
        };
        let (mut covered, mut spared) = (0usize, 0usize);
        for n in 0..6000 {
            let scale = [80.0, 400.0, 1e5, 3e7][n % 4];
            let [a, b, c] = match (n / 4) % 4 {
                0 => [(); 3].map(|_| Vec2::new(next(scale), next(scale))),
                // Corners on quarter pixels (a half: a centre).
                1 => [(); 3].map(|_| (Vec2::new(next(80.0), next(80.0)) * 4.0).round() / 4.0),
                // A sliver along a long edge.
                2 => {
                    let (a, b) = (
                        Vec2::new(next(80.0), next(80.0)),
                        Vec2::new(next(80.0), next(80.0)),
                    );
                    let along = (b - a).perp().normalize_or_zero() * 1e-3;
                    [a, b, a.lerp(b, 0.5 + next(0.5)) + along]
                }
                // An edge nearly parallel to the rows.
                _ => {
                    let a = Vec2::new(next(80.0), next(80.0));
                    let b = a + Vec2::new(next(400.0), next(1e-3));
                    [a, b, Vec2::new(next(80.0), next(80.0))]
                }
            };
            let area = edge(b, c, a);
            if area == 0.0 {
                continue;
            }
            let sign = area.signum();
            let spans = RowSpans::new([a, b, c], sign);
            for y in 0..h {
                let py = y as f32 + 0.5;
                let span = spans.row(py, (0, w - 1));
                for x in 0..w {
                    let p = Vec2::new(x as f32 + 0.5, py);
                    let inside = sign * edge(b, c, p) >= 0.0
                        && sign * edge(c, a, p) >= 0.0
                        && sign * edge(a, b, p) >= 0.0;
                    let in_span = span.is_some_and(|(first, last)| (first..=last).contains(&x));
                    assert!(!inside || in_span, "{a} {b} {c}: ({x}, {y}) outside {span:?}");
                    covered += inside as usize;
                    spared += !in_span as usize;
                }
            }
        }
        // Not vacuous: many pixels covered, many spared.
        assert!(covered > 100_000 && spared > 100_000, "{covered} {spared}");
    }

    /// The cull keeps exactly the triangles whose box holds a pixel centre on screen.
    #[test]
    fn triangles_between_pixel_centres_are_culled() {
        let pixels = |xy: [(f32, f32); 3]| pixel_box(xy.map(|(x, y)| Vec2::new(x, y)), 64, 48);
        let keep = |xy| pixels(xy).is_some();
        // A tenth of a pixel around the centre of pixel (10, 20), and beside it.
        assert!(keep([(10.45, 20.45), (10.55, 20.45), (10.5, 20.55)]));
        assert!(!keep([(10.1, 20.1), (10.4, 20.1), (10.2, 20.4)]));
        // Thin in one axis only: between two rows of centres.
        assert!(!keep([(3.0, 7.6), (30.0, 7.7), (12.0, 8.4)]));
        // Reaching the first and the last centre of the screen, and just short of them.
        assert!(keep([(-5.0, -5.0), (0.5, -5.0), (-5.0, 0.5)]));
        assert!(!keep([(-5.0, -5.0), (0.49, -5.0), (-5.0, 0.49)]));
        assert!(keep([(63.5, 47.5), (70.0, 47.5), (63.5, 50.0)]));
        assert!(!keep([(63.51, 47.0), (70.0, 47.0), (63.6, 50.0)]));
        assert!(!keep([(f32::NAN, 1.0), (5.0, 5.0), (1.0, 5.0)]));
        // The box: the centres held, clipped to the screen.
        assert_eq!(
            pixels([(-9.0, 3.4), (80.0, 3.6), (20.0, 8.0)]),
            Some((0, 3, 63, 7))
        );
    }
}
