//! The G-buffer: what each pixel shows, before lighting.
//!
//! Geometry (the rasterizer) and impostors (the warps) write surfaces here with a depth
//! test, so they occlude each other correctly; [`GBuffer::shade`] then lights every
//! covered pixel once with [`relief_core::shading::Lighting::shade_lanes`] — the same
//! model as the ray-traced reference. An impostor's silhouette pixels, which its texels
//! cover only in part, are kept aside as [`Fragment`]s and blended over what lies
//! behind them once that is lit.
//!
//! The buffer is stored by plane (depth, object, albedo, the normal's three
//! components), not by pixel: clearing writes only the depth plane (a quarter of the
//! bytes), and shading loads eight pixels of each plane into one SIMD register.

use glam::Vec3;
use rayon::prelude::*;
use wide::bytemuck::cast;
use wide::{f32x8, i16x8, i32x8, u32x8};

use crate::EMPTY_DEPTH;
use relief_core::camera::Camera;
use relief_core::frame::{Frame, NO_OBJECT};
use relief_core::hash::ContentHash;
use relief_core::scene::Scene;
use relief_core::shading::{
    LANE_INDEX, LANES, Specular, SurfaceLanes, SurfacePoint, Vec3x8, lane_mask, to_rgb8, to_rgb8_lanes,
};

/// One pixel's nearest surface, as writers give it and readers get it back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GPixel {
    /// View-space depth (distance along the camera's forward axis); [`EMPTY_DEPTH`] if empty
    /// (every value in the buffer is finite).
    pub depth: f32,
    /// Scene object index, or [`NO_OBJECT`].
    pub object: u32,
    /// Linear albedo, 8 bits per channel.
    pub albedo: [u8; 3],
    /// Unit normal in the object's frame (turned into the world when the buffer is
    /// lit; see `SceneObject`'s placements), stored to 16 bits per component: within
    /// 2e-5. A writer may give a shorter one, in its direction: it is normalised when
    /// read.
    pub normal: Vec3,
}

impl GPixel {
    pub const EMPTY: GPixel = GPixel {
        depth: EMPTY_DEPTH,
        object: NO_OBJECT,
        albedo: [0; 3],
        normal: Vec3::ZERO,
    };

    /// True when a surface has been written.
    #[inline]
    pub fn is_covered(&self) -> bool {
        self.depth < EMPTY_DEPTH
    }
}

/// A normal component in `[-1, 1]` as a signed 16-bit fraction.
const NORMAL_SCALE: f32 = 32767.0;

/// The G-buffer's normal encoding: each component a signed 16-bit fraction, within 2e-5
/// (finer than the textures' 8-bit [`encode_normal_rgb8`](relief_core::relief::encode_normal_rgb8)).
#[inline(always)]
fn encode_normal_i16(n: Vec3) -> [i16; 3] {
    (n.clamp(Vec3::NEG_ONE, Vec3::ONE) * NORMAL_SCALE)
        .round()
        .to_array()
        .map(|c| c as i16)
}

#[inline(always)]
fn pack_albedo([r, g, b]: [u8; 3]) -> u32 {
    u32::from_le_bytes([r, g, b, 0])
}

/// A surface's object, albedo and normal as the buffer stores them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stored {
    object: u32,
    albedo: u32,
    normal: [i16; 3],
}

impl Stored {
    /// The scene object.
    pub fn object(&self) -> u32 {
        self.object
    }

    /// `normal` may be shorter than unit (a blend of unit normals): the shading
    /// normalises it. It must be finite.
    #[inline(always)]
    pub fn new(object: u32, albedo: [u8; 3], normal: Vec3) -> Stored {
        Stored {
            object,
            albedo: pack_albedo(albedo),
            normal: encode_normal_i16(normal),
        }
    }

    /// As [`Stored::new`] with the normal in the textures' 8-bit encoding
    /// (`n·127.5 + 127.5` per component, possibly blended): kept as `(2e − 255)·128`,
    /// the same direction at a scale the shading's normalisation removes.
    #[inline(always)]
    pub fn with_encoded_normal(object: u32, albedo: [u8; 3], normal: [u8; 3]) -> Stored {
        Stored {
            object,
            albedo: pack_albedo(albedo),
            normal: normal.map(|e| (2 * e as i16 - 255) * 128),
        }
    }
}

/// [`LANES`] surfaces of one object as the buffer stores them, a pixel's a lane
/// ([`Stored`] eight times): what a texture mapping writes for eight pixels at once.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StoredLanes {
    pub(crate) object: u32,
    /// Packed as [`Stored`]'s albedo.
    pub(crate) albedo: u32x8,
    /// Each component as [`Stored`]'s.
    pub(crate) normal: [i16x8; 3],
}

impl StoredLanes {
    /// [`Stored::with_encoded_normal`] of eight surfaces of `object`: `albedo` packed as
    /// [`Stored`]'s, `normal` each component's 8-bit encoding, a lane a surface.
    #[inline(always)]
    pub(crate) fn with_encoded_normal(object: u32, albedo: u32x8, normal: [u32x8; 3]) -> StoredLanes {
        let encode = |e: u32x8| {
            let e = cast::<u32x8, i32x8>(e);
            i16x8::from_i32x8_saturate((e * i32x8::splat(2) - i32x8::splat(255)) * i32x8::splat(128))
        };
        StoredLanes {
            object,
            albedo,
            normal: normal.map(encode),
        }
    }

    /// Lane `l`'s surface.
    #[inline(always)]
    fn lane(&self, l: usize) -> Stored {
        Stored {
            object: self.object,
            albedo: self.albedo.as_array()[l],
            normal: self.normal.map(|c| c.as_array()[l]),
        }
    }
}

/// Rows of a [`GBuffer`], mutable: the whole buffer or a band of it, so writers can
/// split the work by rows across threads. Pixel `i` is `(i % width, y0 + i / width)`.
pub struct Rows<'a> {
    /// The first row held.
    y0: u32,
    width: usize,
    depth: &'a mut [f32],
    object: &'a mut [u32],
    albedo: &'a mut [u32],
    normal: [&'a mut [i16]; 3],
    /// Partial surfaces written here, for [`GBuffer::add_fragments`].
    fragments: Vec<Fragment>,
}

impl Rows<'_> {
    /// The first row held.
    pub fn y0(&self) -> u32 {
        self.y0
    }

    /// Rows held.
    pub fn rows(&self) -> usize {
        self.depth.len() / self.width.max(1)
    }

    /// The depth at pixel `i` ([`EMPTY_DEPTH`](GPixel::EMPTY) where nothing is).
    #[inline(always)]
    pub fn depth(&self, i: usize) -> f32 {
        self.depth[i]
    }

    /// Writes `pixel` at pixel `i` if it is nearer than what is there; returns whether
    /// it did. Non-finite or non-positive depths and non-finite normals are ignored.
    #[inline(always)]
    pub fn keep_nearer(&mut self, i: usize, pixel: GPixel) -> bool {
        let written = pixel.normal.is_finite() && self.nearer(i, pixel.depth);
        if written {
            self.set(i, pixel);
        }
        written
    }

    /// [`Rows::keep_nearer`] with the attributes in stored form: written when `depth` is
    /// positive and nearer (not NaN).
    #[inline(always)]
    pub fn keep_nearer_stored(&mut self, i: usize, depth: f32, stored: &Stored) -> bool {
        self.keep_nearer_stored_as(i, depth, depth, stored)
    }

    /// [`Rows::keep_nearer_stored`] testing `tested` instead of `depth`: a surface
    /// tested as if farther than it is (see [`Prewarped::behind`](crate::warp::Prewarped::behind)), stored as it is.
    #[inline(always)]
    pub fn keep_nearer_stored_as(&mut self, i: usize, tested: f32, depth: f32, stored: &Stored) -> bool {
        let written = self.nearer(i, tested) && depth > 0.0;
        if written {
            self.set_stored(i, depth, stored);
        }
        written
    }

    /// Adds a surface covering the fraction `coverage` (in `(0, 1)`) of pixel `i`,
    /// tested at `tested`, at `depth`, if it is nearer than what the pixel holds now:
    /// blended over the pixel when the buffer is shaded (see [`Fragment`]). Hand the
    /// fragments to the buffer with [`Rows::into_fragments`] and
    /// [`GBuffer::add_fragments`].
    #[inline]
    pub fn add_fragment(&mut self, i: usize, tested: f32, depth: f32, coverage: f32, stored: &Stored) {
        if self.nearer(i, tested) && depth > 0.0 && coverage > 0.0 {
            self.fragments.push(Fragment {
                pixel: self.y0 as usize * self.width + i,
                tested,
                depth,
                coverage: coverage.min(1.0),
                stored: *stored,
            });
        }
    }

    /// The fragments added to these rows ([`Rows::add_fragment`]).
    pub fn into_fragments(self) -> Vec<Fragment> {
        self.fragments
    }

    /// The one depth test: `depth` positive and nearer than pixel `i`'s (so finite,
    /// and never NaN).
    #[inline(always)]
    fn nearer(&self, i: usize, depth: f32) -> bool {
        depth > 0.0 && depth < self.depth[i]
    }

    /// Writes `pixel` at pixel `i` without a test: for a writer that has done the depth
    /// test itself and knows the depth finite and positive and the normal finite.
    #[inline(always)]
    pub fn set(&mut self, i: usize, pixel: GPixel) {
        self.set_stored(
            i,
            pixel.depth,
            &Stored::new(pixel.object, pixel.albedo, pixel.normal),
        );
    }

    /// [`Rows::keep_nearer_stored`] for the [`LANES`] pixels from `i` whose bits are set
    /// in `lanes` (bit `l` is pixel `i + l`), all with one surface: one vector depth
    /// test, and the group written by vector selects (a flat triangle's pixels — the
    /// ground covers half a frame — cost a few instructions each instead of a test and
    /// six stores, and a leaf's ragged edge no branch a lane). (Not through
    /// `Rows::keep_nearer_lanes_as`: `relief bench raster --objects tree,ground` ran
    /// 2.55–2.63 ms so, against 2.03–2.09.)
    #[inline(always)]
    pub fn keep_nearer_stored_lanes(&mut self, i: usize, lanes: u32, depths: f32x8, stored: &Stored) {
        let group = i..i + LANES;
        let Some(Ok(held)) = self
            .depth
            .get_mut(group.clone())
            .map(<&mut [f32; LANES]>::try_from)
        else {
            // The buffer's last pixels: one at a time.
            for (l, &depth) in depths.to_array().iter().enumerate() {
                if lanes & (1 << l) != 0 && i + l < self.depth.len() {
                    self.keep_nearer_stored(i + l, depth, stored);
                }
            }
            return;
        };
        let old = f32x8::new(*held);
        let nearer = depths.simd_gt(f32x8::ZERO) & depths.simd_lt(old);
        let bits = nearer.to_bitmask() & lanes;
        if bits == 0 {
            return;
        }
        if bits == ALL_LANES {
            *held = depths.to_array();
            let fill = |plane: &mut [u32], value: u32| {
                if let Ok(plane) = <&mut [u32; LANES]>::try_from(&mut plane[group.clone()]) {
                    *plane = [value; LANES];
                }
            };
            fill(self.object, stored.object);
            fill(self.albedo, stored.albedo);
            for (plane, value) in self.normal.iter_mut().zip(stored.normal) {
                if let Ok(plane) = <&mut [i16; LANES]>::try_from(&mut plane[group.clone()]) {
                    *plane = [value; LANES];
                }
            }
            return;
        }
        let mask_u32 = lane_mask(bits);
        *held = cast::<u32x8, f32x8>(mask_u32).select(depths, old).to_array();
        let select_u32 = |plane: &mut [u32], value: u32| {
            if let Ok(plane) = <&mut [u32; LANES]>::try_from(&mut plane[group.clone()]) {
                *plane = mask_u32
                    .select(u32x8::splat(value), u32x8::new(*plane))
                    .to_array();
            }
        };
        select_u32(self.object, stored.object);
        select_u32(self.albedo, stored.albedo);
        // (All ones stay all ones, saturated to 16 bits.)
        let mask_i16 = i16x8::from_i32x8_saturate(cast::<u32x8, i32x8>(mask_u32));
        for (plane, value) in self.normal.iter_mut().zip(stored.normal) {
            if let Ok(plane) = <&mut [i16; LANES]>::try_from(&mut plane[group.clone()]) {
                *plane = mask_i16
                    .select(i16x8::splat(value), i16x8::new(*plane))
                    .to_array();
            }
        }
    }

    /// [`Rows::keep_nearer_stored_as`] for the [`LANES`] pixels from `i` whose bits are
    /// set in `lanes`, each with its own surface (lane `l` of `tested`, `depths` and
    /// `stored`): one vector depth test, and the group written by vector selects.
    #[inline(always)]
    pub(crate) fn keep_nearer_lanes_as(
        &mut self,
        i: usize,
        lanes: u32,
        tested: f32x8,
        depths: f32x8,
        stored: &StoredLanes,
    ) {
        let group = i..i + LANES;
        let Some(Ok(held)) = self
            .depth
            .get_mut(group.clone())
            .map(<&mut [f32; LANES]>::try_from)
        else {
            // The buffer's last pixels: one at a time.
            let (tested, depths) = (tested.to_array(), depths.to_array());
            for l in 0..LANES {
                if lanes & (1 << l) != 0 && i + l < self.depth.len() {
                    self.keep_nearer_stored_as(i + l, tested[l], depths[l], &stored.lane(l));
                }
            }
            return;
        };
        let old = f32x8::new(*held);
        // (As `nearer`, and the stored depth positive; every comparison is false for NaN.)
        let nearer = tested.simd_gt(f32x8::ZERO) & tested.simd_lt(old) & depths.simd_gt(f32x8::ZERO);
        let bits = nearer.to_bitmask() & lanes;
        if bits == 0 {
            return;
        }
        let mask_u32 = lane_mask(bits);
        *held = cast::<u32x8, f32x8>(mask_u32).select(depths, old).to_array();
        let select_u32 = |plane: &mut [u32], value: u32x8| {
            if let Ok(plane) = <&mut [u32; LANES]>::try_from(&mut plane[group.clone()]) {
                *plane = mask_u32.select(value, u32x8::new(*plane)).to_array();
            }
        };
        select_u32(self.object, u32x8::splat(stored.object));
        select_u32(self.albedo, stored.albedo);
        // (All ones stay all ones, saturated to 16 bits.)
        let mask_i16 = i16x8::from_i32x8_saturate(cast::<u32x8, i32x8>(mask_u32));
        for (plane, value) in self.normal.iter_mut().zip(stored.normal) {
            if let Ok(plane) = <&mut [i16; LANES]>::try_from(&mut plane[group.clone()]) {
                *plane = mask_i16.select(value, i16x8::new(*plane)).to_array();
            }
        }
    }

    /// [`Rows::set`] with the attributes already in stored form (a flat triangle's,
    /// encoded once for all its pixels).
    #[inline(always)]
    pub fn set_stored(&mut self, i: usize, depth: f32, stored: &Stored) {
        self.depth[i] = depth;
        self.object[i] = stored.object;
        self.albedo[i] = stored.albedo;
        let [x, y, z] = stored.normal;
        self.normal[0][i] = x;
        self.normal[1][i] = y;
        self.normal[2][i] = z;
    }
}

/// A `width × height` G-buffer, row-major, y down.
/// (Not `PartialEq`: the planes other than depth keep stale values where a pixel is
/// empty.)
#[derive(Debug, Clone)]
pub struct GBuffer {
    pub width: u32,
    pub height: u32,
    /// View depth; [`EMPTY_DEPTH`](GPixel::EMPTY) where nothing is. The other planes
    /// mean something only where this is below it (clearing leaves them).
    depth: Vec<f32>,
    object: Vec<u32>,
    /// RGB8 in the low three bytes.
    albedo: Vec<u32>,
    /// The normal's x, y, z, each `n · 32767` rounded.
    normal: [Vec<i16>; 3],
    /// Surfaces covering part of a pixel, blended over it when shaded.
    fragments: Vec<Fragment>,
}

/// A surface covering part of one pixel — an impostor's silhouette, where its texels
/// cover a fraction of the pixel. It is not written into the buffer, so the pixel keeps
/// what lies behind; [`GBuffer::shade`] lights it and blends it over the pixel's colour
/// by its coverage, where it is still nearer than the pixel's surface. (Written whole,
/// at the nearest texel, a silhouette pixel is all surface or all background: off by a
/// whole pixel's colour wherever the outline falls on the wrong side of its centre.)
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fragment {
    /// Index in the buffer (`y · width + x`).
    pixel: usize,
    /// The depth it is tested at (see [`Rows::keep_nearer_stored_as`]).
    tested: f32,
    depth: f32,
    /// The fraction of the pixel covered, in `(0, 1]`.
    coverage: f32,
    stored: Stored,
}

impl GBuffer {
    /// An empty buffer.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        GBuffer {
            width,
            height,
            depth: vec![EMPTY_DEPTH; n],
            object: vec![NO_OBJECT; n],
            albedo: vec![0; n],
            normal: [vec![0; n], vec![0; n], vec![0; n]],
            fragments: Vec::new(),
        }
    }

    /// Takes the fragments writers added to their [`Rows`] (see
    /// [`Rows::add_fragment`]).
    pub fn add_fragments(&mut self, fragments: impl IntoIterator<Item = Fragment>) {
        self.fragments.extend(fragments);
    }

    /// The fragments of `object` (see [`Fragment`]).
    pub fn fragments_of(&self, object: u32) -> impl Iterator<Item = &Fragment> {
        self.fragments.iter().filter(move |f| f.stored.object == object)
    }

    /// Empties every pixel, keeping the allocation: only the depth plane is written.
    pub fn clear(&mut self) {
        self.fragments.clear();
        self.depth
            .par_chunks_mut(CLEAR_CHUNK)
            .for_each(|chunk| chunk.fill(EMPTY_DEPTH));
    }

    /// The index of the covered pixel `(x, y)`; `None` where nothing is, or outside.
    #[inline]
    fn covered_index(&self, x: u32, y: u32) -> Option<usize> {
        let i = self.index(x as i64, y as i64)?;
        (self.depth[i] < EMPTY_DEPTH).then_some(i)
    }

    /// The index of pixel `(x, y)`, if inside.
    #[inline]
    fn index(&self, x: i64, y: i64) -> Option<usize> {
        let inside = x >= 0 && y >= 0 && x < self.width as i64 && y < self.height as i64;
        inside.then(|| y as usize * self.width as usize + x as usize)
    }

    /// The pixel at `(x, y)` ([`GPixel::EMPTY`] where nothing is, or outside).
    pub fn get(&self, x: u32, y: u32) -> GPixel {
        let Some(i) = self.covered_index(x, y) else {
            return GPixel::EMPTY;
        };
        let [r, g, b, _] = self.albedo[i].to_le_bytes();
        let n = |k: usize| self.normal[k][i] as f32 / NORMAL_SCALE;
        GPixel {
            depth: self.depth[i],
            object: self.object[i],
            albedo: [r, g, b],
            normal: Vec3::new(n(0), n(1), n(2)).normalize_or_zero(),
        }
    }

    /// The pixel at `(x, y)` exactly as stored, to be written back unchanged with
    /// [`GBuffer::write_stored`]; `None` where nothing is (or outside).
    pub fn stored(&self, x: u32, y: u32) -> Option<(f32, Stored)> {
        let i = self.covered_index(x, y)?;
        let stored = Stored {
            object: self.object[i],
            albedo: self.albedo[i],
            normal: [0, 1, 2].map(|k| self.normal[k][i]),
        };
        Some((self.depth[i], stored))
    }

    /// [`GBuffer::write`] of a pixel in stored form.
    pub fn write_stored(&mut self, x: i64, y: i64, depth: f32, stored: &Stored) -> bool {
        self.index(x, y)
            .is_some_and(|i| self.all_rows().keep_nearer_stored(i, depth, stored))
    }

    /// The object at `(x, y)`, or [`NO_OBJECT`] where nothing is (or outside).
    #[inline]
    pub fn object_at(&self, x: u32, y: u32) -> u32 {
        self.covered_index(x, y).map_or(NO_OBJECT, |i| self.object[i])
    }

    /// The depth plane as it is: view depth, [`EMPTY_DEPTH`] where empty. (For checks that
    /// nothing non-finite got in.)
    pub fn depths(&self) -> &[f32] {
        &self.depth
    }

    /// Pixels with a surface.
    pub fn covered(&self) -> usize {
        self.depth.iter().filter(|&&d| d < EMPTY_DEPTH).count()
    }

    /// Writes `pixel` at `(x, y)` if it is nearer than what is there. Returns whether it
    /// was written. Out-of-range coordinates and non-finite or non-positive depths are
    /// ignored, so a caller can never write outside the buffer or poison it with NaN.
    #[inline]
    pub fn write(&mut self, x: i64, y: i64, pixel: GPixel) -> bool {
        self.index(x, y)
            .is_some_and(|i| self.all_rows().keep_nearer(i, pixel))
    }

    /// The whole buffer as one [`Rows`].
    fn all_rows(&mut self) -> Rows<'_> {
        let [nx, ny, nz] = &mut self.normal;
        Rows {
            y0: 0,
            width: self.width as usize,
            depth: &mut self.depth,
            object: &mut self.object,
            albedo: &mut self.albedo,
            normal: [nx, ny, nz],
            fragments: Vec::new(),
        }
    }

    /// The rows `y0..y1` (clamped to the buffer) in bands of `rows_per_band`, each
    /// its own [`Rows`], in order: for writers that split the work by rows across
    /// threads (`into_par_iter`).
    pub fn bands(&mut self, y0: u32, y1: u32, rows_per_band: usize) -> Vec<Rows<'_>> {
        let w = self.width as usize;
        let (y0, y1) = (y0.min(self.height) as usize, y1.min(self.height) as usize);
        let mut rest = self.all_rows();
        let mut bands = Vec::new();
        if w == 0 || y1 <= y0 {
            return bands;
        }
        // Drop the rows before `y0`, then cut a band at a time off the front.
        rest = rest.split_off(y0 * w).1;
        let mut y = y0;
        while y < y1 {
            let rows = rows_per_band.max(1).min(y1 - y);
            let (band, tail) = rest.split_off(rows * w);
            bands.push(band);
            rest = tail;
            y += rows;
        }
        bands
    }

    /// Lights every covered pixel with the scene's lighting and objects' specular
    /// terms; empty pixels get the background.
    pub fn shade(&self, scene: &Scene, camera: &Camera) -> Frame {
        let (w, h) = (self.width as usize, self.height as usize);
        // (Every pixel is written below: no background fill first.)
        let mut frame = Frame {
            width: self.width,
            height: self.height,
            color: vec![[0; 3]; w * h],
            object: vec![0; w * h],
        };
        let shader = RowShader::new(self, scene, camera);
        frame
            .color
            .par_chunks_mut(w.max(1))
            .zip(frame.object.par_chunks_mut(w.max(1)))
            .enumerate()
            .for_each(|(y, (color, object))| shader.row(y, color, object));
        shader.blend_fragments(&mut frame);
        frame
    }
}

/// What lighting one row of a G-buffer needs: the planes, the scene's terms and the
/// camera's rays (the buffer holds the camera's pixels). Points are lit relative to the
/// eye, which may lie far from the world's origin (see `SceneObject`'s frames).
struct RowShader<'a> {
    gbuffer: &'a GBuffer,
    /// The scene's lighting, relative to the eye.
    lighting: relief_core::shading::Lighting,
    /// Specular strength and exponent of each object, by index.
    specular: Vec<(f32, f32)>,
    /// Each object's frame's turn in the world, by index, where it has one (empty
    /// when none has): the buffer holds normals in the objects' frames (see
    /// `SceneObject`'s placements).
    turns: Vec<Option<glam::Mat3>>,
    /// The object count, in every lane (a scene's count fits its `u32` ids).
    objects: u32x8,
    background: [u8; 3],
    camera: &'a Camera,
    /// [`Camera::ray`]'s step from one pixel to the next in a row.
    x_step: Vec3,
}

impl<'a> RowShader<'a> {
    fn new(gbuffer: &'a GBuffer, scene: &'a Scene, camera: &'a Camera) -> Self {
        RowShader {
            gbuffer,
            lighting: scene.lighting.relative_to(camera.eye),
            specular: scene
                .objects
                .iter()
                .map(|o| (o.specular.strength, o.specular.shininess))
                .collect(),
            turns: {
                let turns: Vec<_> = (scene.objects.iter())
                    .map(|o| o.turn().map(glam::Mat3::from_quat))
                    .collect();
                if turns.iter().all(Option::is_none) {
                    Vec::new()
                } else {
                    turns
                }
            },
            objects: u32x8::splat(u32::try_from(scene.objects.len()).unwrap_or(u32::MAX)),
            background: to_rgb8(scene.background),
            camera,
            x_step: camera.ray_x_step(),
        }
    }

    /// Lights row `y` into `color` and `object` (one row each), [`LANES`] pixels at once.
    fn row(&self, y: usize, color: &mut [[u8; 3]], object: &mut [u32]) {
        let g = self.gbuffer;
        let w = g.width as usize;
        // A pixel's position from the eye is `ray · depth`; rays are linear in x.
        let row_start = self.camera.ray(0.5, y as f32 + 0.5);
        let objects = self.objects;
        let row = y * w;
        for x in (0..w).step_by(LANES) {
            let n = LANES.min(w - x);
            let at = row + x..row + x + n;
            let (color, object) = (&mut color[x..x + n], &mut object[x..x + n]);
            let depth = f32x8::new(lanes(&g.depth[at.clone()], EMPTY_DEPTH));
            let ids = lanes(&g.object[at.clone()], NO_OBJECT);
            let id_lanes = u32x8::new(ids);
            let filled = depth.simd_lt(f32x8::splat(EMPTY_DEPTH));
            // Shown: filled by an object of the scene (a writer's unknown index shows
            // the background, as nothing). Lane `l` is bit `l`.
            let shown = filled.to_bitmask() & id_lanes.simd_lt(objects).to_bitmask();
            if shown == 0 {
                for (c, o) in color.iter_mut().zip(object.iter_mut()) {
                    (*c, *o) = (self.background, NO_OBJECT);
                }
                continue;
            }
            let specular_of = |id: u32| self.specular.get(id as usize).copied().unwrap_or_default();
            let one_object = id_lanes.simd_eq(u32x8::splat(ids[0])).to_bitmask() == ALL_LANES;
            let (strength, shininess) = if one_object {
                // (Mostly one object: one look-up.)
                let (s, k) = specular_of(ids[0]);
                (f32x8::splat(s), f32x8::splat(k))
            } else {
                let (mut s, mut k) = ([0.0; LANES], [0.0; LANES]);
                for l in 0..n {
                    (s[l], k[l]) = specular_of(ids[l]);
                }
                (f32x8::new(s), f32x8::new(k))
            };
            let albedo = i32x8::new(lanes(&g.albedo[at.clone()], 0).map(|a| a as i32));
            let channel = |shift: i32| {
                f32x8::from_i32x8((albedo >> shift) & i32x8::splat(0xff)) * f32x8::splat(1.0 / 255.0)
            };
            // (Normalised below: the scale does not matter.)
            let component =
                |k: usize| f32x8::from_i32x8(i32x8::from(i16x8::new(lanes(&g.normal[k][at.clone()], 0))));
            let xs = f32x8::splat(x as f32) + LANE_INDEX;
            let direction = Vec3x8 {
                x: f32x8::splat(row_start.x) + f32x8::splat(self.x_step.x) * xs,
                y: f32x8::splat(row_start.y) + f32x8::splat(self.x_step.y) * xs,
                z: f32x8::splat(row_start.z) + f32x8::splat(self.x_step.z) * xs,
            };
            // (Empty lanes hold a huge depth: keep their positions finite.)
            let depth = filled.select(depth, f32x8::ZERO);
            let surfaces = SurfaceLanes {
                albedo: Vec3x8 {
                    x: channel(0),
                    y: channel(8),
                    z: channel(16),
                },
                normal: self
                    .to_world(
                        Vec3x8 {
                            x: component(0),
                            y: component(1),
                            z: component(2),
                        },
                        &ids[..n],
                    )
                    .normalize_or_zero(),
                position: direction.scale(depth),
                towards_eye: direction.map(|d| -d),
                strength,
                shininess,
            };
            let lit = to_rgb8_lanes(self.lighting.shade_lanes(&surfaces));
            // (Through fixed-size arrays: a slice copy of a length unknown when compiled
            // is a call to `memcpy`, a tenth of the time spent here.)
            if let (ALL_LANES, Ok(color), Ok(object)) = (
                shown,
                <&mut [[u8; 3]; LANES]>::try_from(&mut *color),
                <&mut [u32; LANES]>::try_from(&mut *object),
            ) {
                *color = lit;
                *object = ids;
                continue;
            }
            for l in 0..n {
                let lit_here = shown & (1 << l) != 0;
                color[l] = if lit_here { lit[l] } else { self.background };
                object[l] = if lit_here { ids[l] } else { NO_OBJECT };
            }
        }
    }
}

impl RowShader<'_> {
    /// Object `id`'s frame's turn in the world, where it has one.
    #[inline(always)]
    fn turn(&self, id: u32) -> Option<glam::Mat3> {
        self.turns.get(id as usize).copied().flatten()
    }

    /// Normals of the objects `ids` (one a lane), each in its object's frame, turned
    /// into the world.
    #[inline(always)]
    fn to_world(&self, normals: Vec3x8, ids: &[u32]) -> Vec3x8 {
        if self.turns.is_empty() || ids.iter().all(|&id| self.turn(id).is_none()) {
            return normals;
        }
        // (Rare: a frame turned by a placement. Lane by lane.)
        let (x, y, z) = (normals.x.to_array(), normals.y.to_array(), normals.z.to_array());
        let turned: [Vec3; LANES] = std::array::from_fn(|l| {
            let n = Vec3::new(x[l], y[l], z[l]);
            match ids.get(l).and_then(|&id| self.turn(id)) {
                Some(turn) => turn * n,
                None => n,
            }
        });
        Vec3x8::gather(turned)
    }

    /// Lights the buffer's fragments still in front of their pixels' surfaces and
    /// blends them over `frame` by their coverage, the farthest first; a pixel more
    /// than half covered by one is counted as its object's.
    fn blend_fragments(&self, frame: &mut Frame) {
        let g = self.gbuffer;
        let w = (g.width as usize).max(1);
        let mut shown: Vec<&Fragment> = g
            .fragments
            .iter()
            .filter(|f| f.pixel < g.depth.len() && f.tested < g.depth[f.pixel])
            .collect();
        shown.sort_unstable_by(|a, b| a.pixel.cmp(&b.pixel).then(b.depth.total_cmp(&a.depth)));
        let points: Vec<SurfacePoint> = shown
            .iter()
            .map(|f| {
                let ray = self
                    .camera
                    .ray((f.pixel % w) as f32 + 0.5, (f.pixel / w) as f32 + 0.5);
                let (strength, shininess) = self
                    .specular
                    .get(f.stored.object as usize)
                    .copied()
                    .unwrap_or_default();
                let channel = |shift: u32| ((f.stored.albedo >> shift) & 0xff) as f32 / 255.0;
                SurfacePoint {
                    albedo: Vec3::new(channel(0), channel(8), channel(16)),
                    normal: {
                        let n = Vec3::from(f.stored.normal.map(f32::from));
                        match self.turn(f.stored.object) {
                            Some(turn) => turn * n,
                            None => n,
                        }
                        .normalize_or_zero()
                    },
                    position: ray * f.depth,
                    towards_eye: -ray,
                    specular: Specular { strength, shininess },
                }
            })
            .collect();
        let mut lit = vec![Vec3::ZERO; points.len()];
        self.lighting.shade_all(&points, &mut lit);
        for (f, lit) in shown.into_iter().zip(lit) {
            let under = Vec3::from(frame.color[f.pixel].map(f32::from)) / 255.0;
            frame.color[f.pixel] = to_rgb8(under.lerp(lit, f.coverage));
            if f.coverage > 0.5 && (f.stored.object as usize) < self.specular.len() {
                frame.object[f.pixel] = f.stored.object;
            }
        }
    }
}

/// The bit mask of all [`LANES`] lanes.
const ALL_LANES: u32 = (1 << LANES) - 1;

/// Pixels cleared per task.
const CLEAR_CHUNK: usize = 1 << 16;

/// `values` in the first lanes, `fill` in the rest.
#[inline(always)]
fn lanes<T: Copy>(values: &[T], fill: T) -> [T; LANES] {
    match values.try_into() {
        Ok(full) => full,
        Err(_) => std::array::from_fn(|l| values.get(l).copied().unwrap_or(fill)),
    }
}

impl<'a> Rows<'a> {
    /// Splits after pixel `at`: the pixels before it and those from it on.
    fn split_off(self, at: usize) -> (Rows<'a>, Rows<'a>) {
        let (d0, d1) = self.depth.split_at_mut(at);
        let (o0, o1) = self.object.split_at_mut(at);
        let (a0, a1) = self.albedo.split_at_mut(at);
        let [nx, ny, nz] = self.normal;
        let (x0, x1) = nx.split_at_mut(at);
        let (y0, y1) = ny.split_at_mut(at);
        let (z0, z1) = nz.split_at_mut(at);
        let w = self.width;
        (
            Rows {
                y0: self.y0,
                width: w,
                depth: d0,
                object: o0,
                albedo: a0,
                normal: [x0, y0, z0],
                fragments: self.fragments,
            },
            Rows {
                y0: self.y0 + (at / w.max(1)) as u32,
                width: w,
                depth: d1,
                object: o1,
                albedo: a1,
                normal: [x1, y1, z1],
                fragments: Vec::new(),
            },
        )
    }
}

/// A digest of the surfaces buffers hold, to the bit: for each buffer
/// [`added`](SurfaceDigest::add), how many pixels have a surface, then each one's index,
/// depth, object, albedo and normal, as little-endian words (what a pixel without a
/// surface holds means nothing, and is left out). Two runs whose digests are equal drew
/// the same surfaces: how a writer made faster shows that it draws what it did
/// (`relief bench raster`'s `gbuffer_digest`). Fragments are left out: the rasterizer,
/// which this serves, writes none.
#[derive(Default)]
pub struct SurfaceDigest(blake3::Hasher);

/// Bytes [`SurfaceDigest`] gathers before it hashes them (a call to the hasher for each
/// pixel's 26 bytes would be one call per pixel).
const DIGEST_CHUNK: usize = 1 << 16;

impl SurfaceDigest {
    pub fn new() -> SurfaceDigest {
        SurfaceDigest::default()
    }

    /// Adds `gbuffer`'s surfaces.
    pub fn add(&mut self, gbuffer: &GBuffer) {
        let g = gbuffer;
        self.0.update(&(g.covered() as u64).to_le_bytes());
        let mut bytes = Vec::with_capacity(DIGEST_CHUNK);
        for i in (0..g.depth.len()).filter(|&i| g.depth[i] < EMPTY_DEPTH) {
            bytes.extend_from_slice(&(i as u64).to_le_bytes());
            bytes.extend_from_slice(&g.depth[i].to_bits().to_le_bytes());
            bytes.extend_from_slice(&g.object[i].to_le_bytes());
            bytes.extend_from_slice(&g.albedo[i].to_le_bytes());
            for plane in &g.normal {
                bytes.extend_from_slice(&plane[i].to_le_bytes());
            }
            if bytes.len() >= DIGEST_CHUNK {
                self.0.update(&bytes);
                bytes.clear();
            }
        }
        self.0.update(&bytes);
    }

    /// The digest of the buffers added so far.
    pub fn finish(&self) -> ContentHash {
        ContentHash(*self.0.finalize().as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pixels_round_trip_and_keep_the_nearer() {
        let mut g = GBuffer::new(7, 5);
        let p = GPixel {
            depth: 2.0,
            object: 3,
            albedo: [10, 20, 30],
            normal: Vec3::new(0.6, -0.8, 0.0),
        };
        assert!(g.write(6, 4, p));
        let back = g.get(6, 4);
        assert_eq!((back.depth, back.object, back.albedo), (2.0, 3, [10, 20, 30]));
        assert!(back.normal.abs_diff_eq(p.normal, 2e-5), "{}", back.normal);
        // Farther, NaN, zero depth, NaN normal, outside: not written.
        assert!(!g.write(6, 4, GPixel { depth: 3.0, ..p }));
        assert!(!g.write(6, 4, GPixel { depth: f32::NAN, ..p }));
        assert!(!g.write(0, 0, GPixel { depth: 0.0, ..p }));
        assert!(!g.write(
            0,
            0,
            GPixel {
                normal: Vec3::NAN,
                ..p
            }
        ));
        assert!(!g.write(7, 0, p) && !g.write(-1, 0, p));
        assert_eq!(g.covered(), 1);
        assert!(g.write(
            6,
            4,
            GPixel {
                depth: 1.0,
                object: 1,
                ..p
            }
        ));
        assert_eq!(g.object_at(6, 4), 1);
        g.clear();
        assert_eq!(g.covered(), 0);
        assert_eq!((g.get(6, 4), g.object_at(6, 4)), (GPixel::EMPTY, NO_OBJECT));
    }

    #[test]
    fn bands_cover_the_rows_asked_once() {
        let mut g = GBuffer::new(3, 10);
        let bands = g.bands(2, 9, 3);
        let spans: Vec<(u32, usize)> = bands.iter().map(|b| (b.y0(), b.rows())).collect();
        assert_eq!(spans, vec![(2, 3), (5, 3), (8, 1)]);
        for mut band in bands {
            let y0 = band.y0();
            for i in 0..band.rows() * 3 {
                band.keep_nearer(
                    i,
                    GPixel {
                        depth: 1.0,
                        object: y0,
                        albedo: [0; 3],
                        normal: Vec3::Z,
                    },
                );
            }
        }
        for y in 0..10 {
            let expected = match y {
                2..=4 => 2,
                5..=7 => 5,
                8 => 8,
                _ => NO_OBJECT,
            };
            assert_eq!(g.object_at(1, y), expected, "row {y}");
        }
        assert!(g.bands(12, 20, 4).is_empty());
    }

    /// Shading 8 pixels at a time gives what the model gives each pixel alone, on rows
    /// that are not a multiple of 8 long, with empty pixels and unknown objects between.
    #[test]
    fn shading_lights_each_covered_pixel_as_the_model_does() {
        let scene = relief_core::scene::Scene::load("default").unwrap();
        let (w, h) = (13u32, 3u32);
        let camera = Camera::look_at(Vec3::new(0.0, 2.0, 9.0), Vec3::ZERO, Vec3::Y, 60.0, w, h).unwrap();
        let mut g = GBuffer::new(w, h);
        let mut k = 0u32;
        for y in 0..h {
            for x in 0..w {
                k += 1;
                if k.is_multiple_of(5) {
                    continue; // empty
                }
                let a = k as f32 * 0.7;
                let object = if k.is_multiple_of(7) {
                    99
                } else {
                    k % scene.objects.len() as u32
                };
                g.write(
                    x as i64,
                    y as i64,
                    GPixel {
                        depth: 2.0 + k as f32 * 0.1,
                        object,
                        albedo: [(k * 37 % 256) as u8, (k * 91 % 256) as u8, (k * 13 % 256) as u8],
                        normal: Vec3::new(a.sin(), a.cos(), 0.4).normalize(),
                    },
                );
            }
        }
        let frame = g.shade(&scene, &camera);
        let background = to_rgb8(scene.background);
        let (mut lit, mut unknown) = (0, 0);
        for y in 0..h {
            for x in 0..w {
                let at = (y * w + x) as usize;
                let p = g.get(x, y);
                let Some(o) = scene.objects.get(p.object as usize).filter(|_| p.is_covered()) else {
                    unknown += (p.is_covered()) as usize;
                    assert_eq!(
                        (frame.color[at], frame.object[at]),
                        (background, NO_OBJECT),
                        "({x}, {y})"
                    );
                    continue;
                };
                let unit = camera.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
                // (Depth is along the view axis.)
                let direction = unit / unit.dot(camera.forward);
                let point = relief_core::shading::SurfacePoint {
                    albedo: Vec3::from(p.albedo.map(f32::from)) / 255.0,
                    normal: p.normal,
                    position: direction * p.depth,
                    towards_eye: -direction,
                    specular: o.specular,
                };
                let expected = to_rgb8(scene.lighting.relative_to(camera.eye).shade(&point));
                let close = frame.color[at]
                    .iter()
                    .zip(expected)
                    .all(|(&a, b)| a.abs_diff(b) <= 1);
                assert!(close, "({x}, {y}): {:?} vs {expected:?}", frame.color[at]);
                assert_eq!(frame.object[at], p.object);
                lit += 1;
            }
        }
        assert!(lit > 20 && unknown > 2, "{lit} lit, {unknown} unknown");
    }

    /// A fragment is lit as the same surface written whole would be, and blended over
    /// what its pixel shows by its coverage, the nearer of two on top; one behind the
    /// pixel's surface is hidden; a pixel more than half covered is counted as the
    /// fragment's object.
    #[test]
    fn fragments_blend_by_coverage_over_what_lies_behind() {
        let scene = relief_core::scene::Scene::load("default").unwrap();
        let camera = Camera::look_at(Vec3::new(0.0, 2.0, 9.0), Vec3::ZERO, Vec3::Y, 60.0, 4, 1).unwrap();
        let surface = |object: u32, red: u8| Stored::new(object, [red, 90, 40], Vec3::new(0.3, 0.8, 0.5));
        let (back, front, near, far) = (surface(0, 200), surface(1, 30), surface(2, 120), surface(3, 250));
        // What each surface looks like written whole at each pixel, at its depth.
        let whole = |stored: &Stored, depth: f32| {
            let mut g = GBuffer::new(4, 1);
            let mut rows = g.all_rows();
            for i in 0..4 {
                rows.set_stored(i, depth, stored);
            }
            g.shade(&scene, &camera).color
        };
        let mut g = GBuffer::new(4, 1);
        let mut rows = g.all_rows();
        rows.add_fragment(0, 3.0, 3.0, 0.25, &front);
        rows.set_stored(1, 5.0, &back);
        rows.add_fragment(1, 3.0, 3.0, 0.75, &front);
        // Added before the nearer surface that hides it.
        rows.add_fragment(2, 3.0, 3.0, 0.75, &front);
        rows.set_stored(2, 2.0, &back);
        rows.add_fragment(3, 4.0, 4.0, 0.5, &far);
        rows.add_fragment(3, 3.0, 3.0, 0.5, &near);
        let fragments = rows.into_fragments();
        assert_eq!(fragments.len(), 5);
        g.add_fragments(fragments);
        let frame = g.shade(&scene, &camera);
        let background = Vec3::from(to_rgb8(scene.background).map(f32::from)) / 255.0;
        let colour = |c: [u8; 3]| Vec3::from(c.map(f32::from)) / 255.0;
        let over = |under: Vec3, top: [u8; 3], coverage: f32| under.lerp(colour(top), coverage);
        let expected = [
            over(background, whole(&front, 3.0)[0], 0.25),
            over(colour(whole(&back, 5.0)[1]), whole(&front, 3.0)[1], 0.75),
            colour(whole(&back, 2.0)[2]),
            over(
                over(background, whole(&far, 4.0)[3], 0.5),
                whole(&near, 3.0)[3],
                0.5,
            ),
        ];
        for (i, expected) in expected.into_iter().enumerate() {
            let close = frame.color[i]
                .iter()
                .zip(to_rgb8(expected))
                .all(|(&a, b)| a.abs_diff(b) <= 2);
            assert!(
                close,
                "pixel {i}: {:?} vs {:?}",
                frame.color[i],
                to_rgb8(expected)
            );
        }
        assert_eq!(frame.object, [NO_OBJECT, 1, 0, NO_OBJECT]);
    }

    /// A pixel read in stored form writes back unchanged; stored writes keep the depth
    /// test and refuse NaN and non-positive depths.
    #[test]
    fn stored_pixels_write_back_unchanged() {
        let mut g = GBuffer::new(4, 4);
        let p = GPixel {
            depth: 3.0,
            object: 2,
            albedo: [1, 2, 3],
            normal: Vec3::new(0.0, 0.6, -0.8),
        };
        assert!(g.write(1, 2, p));
        let (depth, stored) = g.stored(1, 2).unwrap();
        assert_eq!((depth, stored.object()), (3.0, 2));
        let mut h = GBuffer::new(4, 4);
        assert!(h.write_stored(1, 2, depth, &stored));
        assert_eq!(h.stored(1, 2), g.stored(1, 2));
        for bad in [f32::NAN, 0.0, -1.0, 3.0, 4.0] {
            assert!(!h.write_stored(1, 2, bad, &stored), "{bad}");
        }
        assert!(!h.write_stored(4, 0, 1.0, &stored) && !h.write_stored(0, -1, 1.0, &stored));
        assert_eq!((g.stored(0, 0), g.stored(9, 9)), (None, None));
    }

    /// Eight pixels at once write what eight single tests would: only lanes asked for,
    /// only where nearer and positive, whole groups and the buffer's last pixels alike.
    #[test]
    fn lanes_of_one_surface_write_as_single_pixels_do() {
        let stored = Stored::new(3, [9, 8, 7], Vec3::new(0.0, 0.0, 1.0));
        let other = Stored::new(1, [1, 1, 1], Vec3::X);
        let depths = f32x8::new([1.0, 5.0, f32::NAN, -1.0, 2.0, 2.0, 0.0, 4.0]);
        // 10×2: the group from pixel 16 runs past the buffer's end.
        for (start, lanes) in [(0, ALL_LANES), (3, 0b1011_0111), (16, ALL_LANES), (12, 0)] {
            let (mut vector, mut single) = (GBuffer::new(10, 2), GBuffer::new(10, 2));
            for g in [&mut vector, &mut single] {
                for k in 0..20 {
                    g.write_stored(k % 10, k / 10, 3.0, &other);
                }
            }
            vector
                .all_rows()
                .keep_nearer_stored_lanes(start, lanes, depths, &stored);
            let mut rows = single.all_rows();
            for (l, &depth) in depths.to_array().iter().enumerate() {
                if lanes & (1 << l) != 0 && start + l < 20 {
                    rows.keep_nearer_stored(start + l, depth, &stored);
                }
            }
            for k in 0..20 {
                let (x, y) = (k % 10, k / 10);
                assert_eq!(
                    vector.stored(x, y),
                    single.stored(x, y),
                    "group {start}, pixel {k}"
                );
            }
        }
        // A whole group nearer: every plane of every pixel written.
        let mut g = GBuffer::new(9, 1);
        g.all_rows()
            .keep_nearer_stored_lanes(1, ALL_LANES, f32x8::splat(2.0), &stored);
        assert_eq!(g.stored(0, 0), None);
        for x in 1..9 {
            assert_eq!(g.stored(x, 0), Some((2.0, stored)), "pixel {x}");
        }
    }

    /// The digest tells surfaces apart by any bit of any attribute and by where they
    /// are, and leaves out what an emptied pixel still holds.
    #[test]
    fn the_surface_digest_sees_every_bit_and_no_empty_pixel() {
        let digest = |g: &GBuffer| {
            let mut d = SurfaceDigest::new();
            d.add(g);
            d.finish()
        };
        let p = GPixel {
            depth: 2.0,
            object: 3,
            albedo: [10, 20, 30],
            normal: Vec3::new(0.6, -0.8, 0.0),
        };
        let drawn = |p: GPixel, x: i64| drawn_at(p, x, 2);
        let once = digest(&drawn(p, 1));
        assert_eq!(digest(&drawn(p, 1)), once);
        for other in [
            GPixel {
                depth: f32::from_bits(2.0f32.to_bits() + 1),
                ..p
            },
            GPixel { object: 4, ..p },
            GPixel {
                albedo: [10, 20, 31],
                ..p
            },
            GPixel {
                normal: Vec3::new(0.6, -0.8, 1e-4),
                ..p
            },
        ] {
            assert_ne!(digest(&drawn(other, 1)), once, "{other:?}");
        }
        assert_ne!(digest(&drawn(p, 2)), once, "moved");
        // A pixel drawn, then cleared, and another drawn: as if the first never was.
        let mut cleared = drawn(GPixel { object: 9, ..p }, 1);
        cleared.clear();
        assert!(cleared.write(3, 0, p));
        assert_eq!(digest(&cleared), digest(&drawn_at(p, 3, 0)));
    }

    /// A 4 × 3 buffer holding `p` at `(x, y)`.
    fn drawn_at(p: GPixel, x: i64, y: i64) -> GBuffer {
        let mut g = GBuffer::new(4, 3);
        assert!(g.write(x, y, p));
        g
    }
}
