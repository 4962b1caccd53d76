//! A texture's planes on the wire: raw, or each one zstd frame — compressed once where
//! the texture is baked, then kept and forwarded as they came.
//!
//! A worker sends [`compressed`] planes; the server checks them (they must decompress
//! to their sizes, no more) and hands the same bytes to every client that asks for
//! them so (`ImpostorRequest.zstd_planes`), [`raw`] ones to any other. Compressing
//! once per texture, rather than once per client it goes to, took 45 % of a busy
//! server's time off it (64 clients of `relief load`).
//!
//! Compressed planes are predicted first where that pays ([`pb::PlaneEncoding::ZstdDelta`]
//! in the proto: each byte as its difference from the same byte of the texel to its
//! left): a smooth surface's normals and 16-bit depths then take a third to a half of
//! the bytes, a rough one's about as many.

use std::borrow::Cow;

use relief_core::relief::DepthBits;
use tonic::Status;
use tonic::codegen::Bytes;

use crate::pb;

/// The zstd level of a texture's planes: the fastest, since a worker compresses every
/// texture it bakes (level 1 keeps most of what higher levels save on these planes).
pub const PLANE_ZSTD_LEVEL: i32 = 1;

/// How a texture's three planes are laid out: rows of `width` texels of
/// `texel_bytes` bytes each (albedo, normal, depth).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct PlaneLayout {
    pub(crate) width: usize,
    pub(crate) texels: usize,
    pub(crate) texel_bytes: [usize; 3],
}

impl PlaneLayout {
    /// The planes of a `width` × `height` texture of `depth_bits` depth.
    pub(crate) fn new(width: u32, height: u32, depth_bits: DepthBits) -> PlaneLayout {
        let depth_bytes = match depth_bits {
            DepthBits::Eight => 1,
            DepthBits::Sixteen => 2,
        };
        PlaneLayout {
            width: width as usize,
            texels: width as usize * height as usize,
            texel_bytes: [3, 3, depth_bytes],
        }
    }

    /// The bytes of plane `k` (0 albedo, 1 normal, 2 depth).
    pub(crate) fn size(&self, k: usize) -> usize {
        self.texels * self.texel_bytes[k]
    }
}

/// The order of a predicted plane's bytes (rows of `width` texels of `texel_bytes`
/// bytes, `len` in all): each byte's index in the plane, lane by lane (every texel's
/// first byte, then every texel's second, ...), and whether it starts a row (its left
/// neighbour counts as 0). The one definition [`delta`] and [`undelta`] share.
fn predicted_order(len: usize, width: usize, texel_bytes: usize) -> impl Iterator<Item = (usize, bool)> {
    let texels = len / texel_bytes;
    (0..texel_bytes)
        .flat_map(move |lane| (0..texels).map(move |t| (t * texel_bytes + lane, t % width.max(1) == 0)))
}

/// `plane` predicted: its bytes in [`predicted_order`], each the difference from the
/// same byte of the texel to its left. Undone by [`undelta`].
fn delta(plane: &[u8], width: usize, texel_bytes: usize) -> Vec<u8> {
    debug_assert_eq!(plane.len() % texel_bytes, 0, "whole texels");
    let mut left = 0u8;
    predicted_order(plane.len(), width, texel_bytes)
        .map(|(k, row_start)| {
            let (byte, before) = (plane[k], if row_start { 0 } else { left });
            left = byte;
            byte.wrapping_sub(before)
        })
        .collect()
}

/// The plane [`delta`] predicted, restored.
fn undelta(coded: &[u8], width: usize, texel_bytes: usize) -> Vec<u8> {
    debug_assert_eq!(coded.len() % texel_bytes, 0, "whole texels");
    let mut plane = vec![0u8; coded.len()];
    let mut left = 0u8;
    for (&difference, (k, row_start)) in coded.iter().zip(predicted_order(coded.len(), width, texel_bytes)) {
        left = if row_start { 0 } else { left }.wrapping_add(difference);
        plane[k] = left;
    }
    plane
}

/// `texture` with its planes compressed (as it is, when they are already): each one
/// zstd frame, of the predicted planes (each byte less the same byte of the texel to
/// its left) when those come out smaller.
pub fn compressed(texture: pb::ReliefTexture) -> pb::ReliefTexture {
    if texture.encoding != pb::PlaneEncoding::Raw as i32 {
        return texture;
    }
    let raw = [&texture.albedo, &texture.normal, &texture.depth];
    // (zstd fails only out of memory: then the planes go as they are.)
    let Some(plain) = squeezed(raw) else {
        return texture;
    };
    // (Only planes of their layout's sizes are predicted; a worker's always are.)
    let layout = DepthBits::from_bits(texture.depth_bits)
        .ok()
        .map(|bits| PlaneLayout::new(texture.width, texture.height, bits))
        .filter(|layout| (0..3).all(|k| raw[k].len() == layout.size(k)));
    let predicted = layout.and_then(|layout| {
        squeezed(std::array::from_fn::<_, 3, _>(|k| {
            delta(raw[k], layout.width, layout.texel_bytes[k])
        }))
    });
    let total = |planes: &[Bytes; 3]| planes.iter().map(Bytes::len).sum::<usize>();
    let ([albedo, normal, depth], encoding) = match predicted {
        Some(predicted) if total(&predicted) < total(&plain) => (predicted, pb::PlaneEncoding::ZstdDelta),
        _ => (plain, pb::PlaneEncoding::Zstd),
    };
    pb::ReliefTexture {
        albedo,
        normal,
        depth,
        encoding: encoding.into(),
        ..texture
    }
}

/// Each of `planes` as one zstd frame; `None` when zstd fails.
fn squeezed<P: AsRef<[u8]>>(planes: [P; 3]) -> Option<[Bytes; 3]> {
    let [albedo, normal, depth] = planes.map(|plane| zstd::bulk::compress(plane.as_ref(), PLANE_ZSTD_LEVEL));
    Some([albedo.ok()?, normal.ok()?, depth.ok()?].map(Bytes::from))
}

/// `texture` with raw planes (decompressed, when they came compressed), every field
/// checked. `field` prefixes the names in errors.
pub fn raw(field: &str, texture: &pb::ReliefTexture) -> Result<pb::ReliefTexture, Status> {
    let [albedo, normal, depth] = crate::convert::checked(field, texture, Planes::Raw)?.planes;
    if texture.encoding == pb::PlaneEncoding::Raw as i32 {
        return Ok(texture.clone());
    }
    let bytes = |plane: Cow<'_, [u8]>| Bytes::from(plane.into_owned());
    Ok(pb::ReliefTexture {
        albedo: bytes(albedo),
        normal: bytes(normal),
        depth: bytes(depth),
        encoding: pb::PlaneEncoding::Raw.into(),
        ..texture.clone()
    })
}

/// The plane encodings a client reads (`ImpostorRequest.zstd_planes` and
/// `zstd_delta_planes`); raw ones, always.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ReadsPlanes {
    pub zstd: bool,
    pub zstd_delta: bool,
}

impl ReadsPlanes {
    /// Whether planes encoded `encoding` can go to this client as they are.
    pub fn reads(self, encoding: i32) -> bool {
        match pb::PlaneEncoding::try_from(encoding) {
            Ok(pb::PlaneEncoding::Raw) => true,
            Ok(pb::PlaneEncoding::Zstd) => self.zstd,
            Ok(pb::PlaneEncoding::ZstdDelta) => self.zstd && self.zstd_delta,
            Err(_) => false,
        }
    }
}

/// What [`planes`] returns of a texture's planes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Planes {
    /// Raw: decompressed, and the prediction undone.
    Raw,
    /// Decompressed only, to be checked and dropped (prediction keeps a plane's size).
    Checked,
}

/// The planes of `texture` as raw bytes (borrowed when they came raw; with
/// [`Planes::Checked`], still predicted if they came so, but for the depth plane of a
/// texture that lists what its rim hides), each checked to be its
/// `layout`'s size: a compressed plane is decompressed into no more than its size, so a
/// small message cannot claim a huge one.
pub(crate) fn planes<'a>(
    field: &str,
    texture: &'a pb::ReliefTexture,
    layout: PlaneLayout,
    wanted: Planes,
) -> Result<[Cow<'a, [u8]>; 3], Status> {
    let invalid = |f: &str, problem: String| crate::convert::invalid(&format!("{field}.{f}"), problem);
    let (compressed, predicted) = match pb::PlaneEncoding::try_from(texture.encoding) {
        Ok(pb::PlaneEncoding::Raw) => (false, false),
        Ok(pb::PlaneEncoding::Zstd) => (true, false),
        Ok(pb::PlaneEncoding::ZstdDelta) => (true, true),
        Err(_) => {
            return Err(invalid(
                "encoding",
                format!("{} is not RAW, ZSTD or ZSTD_DELTA", texture.encoding),
            ));
        }
    };
    let plane = |k: usize, f: &str, bytes: &'a Bytes| -> Result<Cow<'a, [u8]>, Status> {
        let size = layout.size(k);
        let bytes: Cow<'a, [u8]> = if compressed {
            Cow::Owned(
                zstd::bulk::decompress(bytes, size)
                    .map_err(|e| invalid(f, format!("not a zstd frame of at most {size} bytes: {e}")))?,
            )
        } else {
            Cow::Borrowed(&bytes[..])
        };
        if bytes.len() != size {
            return Err(invalid(f, format!("{} bytes, expected {size}", bytes.len())));
        }
        // (Checked only, the depth plane of a texture listing what its rim hides is
        // still raw: the list is checked against it.)
        let hides = k == 2 && !texture.hidden_texels.is_empty();
        Ok(if predicted && (wanted == Planes::Raw || hides) {
            Cow::Owned(undelta(&bytes, layout.width, layout.texel_bytes[k]))
        } else {
            bytes
        })
    };
    Ok([
        plane(0, "albedo", &texture.albedo)?,
        plane(1, "normal", &texture.normal)?,
        plane(2, "depth", &texture.depth)?,
    ])
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use relief_core::bounds::Aabb;
    use relief_core::relief::{DepthBits, ReliefTexture, SourceCamera, SourceProjection};

    use super::*;
    use crate::convert::{check_texture_pb, texture_from_pb, texture_to_pb};

    fn texture(bits: DepthBits) -> ReliefTexture {
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let eye = Vec3::new(0.5, 1.0, 4.0);
        let camera = SourceCamera::facing(eye, &bounds, 40, 30, SourceProjection::Orthographic).unwrap();
        let mut t = ReliefTexture::empty(camera, bits, eye);
        for k in 0..t.depth.len() / 2 {
            t.depth[k] = (k % 200) as u16;
            t.albedo[k] = [k as u8, 7, 9];
            t.normal[k] = [128, 128, 255];
        }
        t
    }

    /// Compressed planes decode to the texture they came from, and back to the raw
    /// message; each plane is smaller.
    #[test]
    fn compressed_planes_round_trip() {
        for bits in [DepthBits::Eight, DepthBits::Sixteen] {
            let t = texture(bits);
            let wire = texture_to_pb(&t);
            let small = compressed(wire.clone());
            // (Its ramps predict well.)
            assert_eq!(small.encoding, pb::PlaneEncoding::ZstdDelta as i32);
            assert!(small.albedo.len() < wire.albedo.len() / 2);
            assert!(small.depth.len() < wire.depth.len() / 2);
            assert_eq!(texture_from_pb("texture", &small).unwrap(), t);
            assert_eq!(raw("texture", &small).unwrap(), wire);
            assert_eq!(compressed(small.clone()), small, "compressed once only");
        }
    }

    /// Prediction is undone exactly, whatever the bytes, rows and texel sizes.
    #[test]
    fn delta_is_undone_exactly() {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut random = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state as u8
        };
        for (width, height, texel_bytes) in [(1, 1, 1), (7, 3, 2), (5, 9, 3), (64, 2, 1)] {
            let plane: Vec<u8> = (0..width * height * texel_bytes).map(|_| random()).collect();
            let coded = delta(&plane, width, texel_bytes);
            assert_eq!(
                undelta(&coded, width, texel_bytes),
                plane,
                "{width}×{height}×{texel_bytes}"
            );
        }
        // A texel's bytes go to their lanes, each row from 0.
        assert_eq!(delta(&[1, 10, 3, 13, 5, 20], 3, 2), [1, 2, 2, 10, 3, 7]);
        assert_eq!(delta(&[1, 3, 5, 7], 2, 1), [1, 2, 5, 2]);
    }

    /// A smooth surface's planes go predicted, and take well under the bytes plain zstd
    /// takes; noise goes plain, predicted or not about as large.
    #[test]
    fn smooth_planes_go_predicted_and_noise_plain() {
        let smooth = {
            let mut t = texture(DepthBits::Sixteen);
            let (w, h) = (t.camera.width as usize, t.camera.height as usize);
            for j in 0..h {
                for i in 0..w {
                    let k = j * w + i;
                    t.depth[k] = (3000 + 37 * i + 53 * j + (i * j) % 5) as u16;
                    t.normal[k] = [(100 + i) as u8, (90 + j) as u8, 200];
                    t.albedo[k] = [200, 40, 40];
                }
            }
            texture_to_pb(&t)
        };
        let small = compressed(smooth.clone());
        assert_eq!(small.encoding, pb::PlaneEncoding::ZstdDelta as i32);
        let plain = |plane: &Bytes| zstd::bulk::compress(plane, PLANE_ZSTD_LEVEL).unwrap().len();
        assert!(
            2 * small.depth.len() < plain(&smooth.depth),
            "{} bytes",
            small.depth.len()
        );
        assert!(
            2 * small.normal.len() < plain(&smooth.normal),
            "{} bytes",
            small.normal.len()
        );
        assert_eq!(raw("texture", &small).unwrap(), smooth);
        let noise = {
            let mut t = texture(DepthBits::Eight);
            let mut state = 0u64;
            for k in 0..t.depth.len() {
                // (splitmix64: every byte noise.)
                state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
                let mut z = state;
                z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                let [a, b, c, d, e, f, g, _] = (z ^ (z >> 31)).to_le_bytes();
                t.albedo[k] = [a, b, c];
                t.normal[k] = [d, e, f];
                t.depth[k] = u16::from(g % 255);
            }
            texture_to_pb(&t)
        };
        let small = compressed(noise.clone());
        assert_eq!(small.encoding, pb::PlaneEncoding::Zstd as i32);
        assert_eq!(raw("texture", &small).unwrap(), noise);
    }

    /// A compressed plane that decompresses to more (or less) than its size, bytes
    /// that are no zstd frame, or an unknown encoding: refused, naming the field.
    #[test]
    fn bad_compressed_planes_are_named() {
        let small = compressed(texture_to_pb(&texture(DepthBits::Eight)));
        let refused =
            |t: &pb::ReliefTexture| check_texture_pb("texture", t).unwrap_err().message().to_string();
        // 100 MB of zeros in a few kB.
        let bomb = zstd::bulk::compress(&vec![0u8; 100 << 20], PLANE_ZSTD_LEVEL).unwrap();
        assert!(bomb.len() < 100 << 10);
        let with_albedo = |albedo: Vec<u8>| pb::ReliefTexture {
            albedo: albedo.into(),
            ..small.clone()
        };
        assert!(refused(&with_albedo(bomb)).contains("`texture.albedo`"));
        let short = zstd::bulk::compress(&[1, 2, 3], PLANE_ZSTD_LEVEL).unwrap();
        assert!(refused(&with_albedo(short)).contains("`texture.albedo`: 3 bytes"));
        assert!(refused(&with_albedo(vec![1, 2, 3, 4, 5])).contains("`texture.albedo`"));
        let unknown = pb::ReliefTexture {
            encoding: 7,
            ..small.clone()
        };
        assert!(refused(&unknown).contains("`texture.encoding`"));
        assert!(raw("texture", &unknown).is_err());
    }
}
