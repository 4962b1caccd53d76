//! A texture's planes on the wire: raw, or each one zstd frame — compressed once where
//! the texture is baked, then kept and forwarded as they came.
//!
//! A worker sends [`compressed`] planes; the server checks them (they must decompress
//! to their sizes, no more) and hands the same bytes to every client that asks for
//! them so (`ImpostorRequest.zstd_planes`), [`raw`] ones to any other. Compressing
//! once per texture, rather than once per client it goes to, took 45 % of a busy
//! server's time off it (64 clients of `relief load`).

use std::borrow::Cow;

use tonic::Status;
use tonic::codegen::Bytes;

use crate::pb;

/// The zstd level of a texture's planes: the fastest, since a worker compresses every
/// texture it bakes (level 1 keeps most of what higher levels save on these planes).
pub const PLANE_ZSTD_LEVEL: i32 = 1;

/// `texture` with its planes compressed (as it is, when they are already).
pub fn compressed(texture: pb::ReliefTexture) -> pb::ReliefTexture {
    if texture.encoding != pb::PlaneEncoding::Raw as i32 {
        return texture;
    }
    let squeeze = |plane: &Bytes| zstd::bulk::compress(plane, PLANE_ZSTD_LEVEL).map(Bytes::from);
    match (
        squeeze(&texture.albedo),
        squeeze(&texture.normal),
        squeeze(&texture.depth),
    ) {
        (Ok(albedo), Ok(normal), Ok(depth)) => pb::ReliefTexture {
            albedo,
            normal,
            depth,
            encoding: pb::PlaneEncoding::Zstd.into(),
            ..texture
        },
        // (zstd fails only out of memory: then the planes go as they are.)
        _ => texture,
    }
}

/// `texture` with raw planes (decompressed, when they came compressed), every field
/// checked. `field` prefixes the names in errors.
pub fn raw(field: &str, texture: &pb::ReliefTexture) -> Result<pb::ReliefTexture, Status> {
    let [albedo, normal, depth] = crate::convert::checked(field, texture)?.planes;
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

/// The planes of `texture` as raw bytes (borrowed when they came raw), each checked to
/// be `sizes` (albedo, normal, depth) bytes: a compressed plane is decompressed into no
/// more than its size, so a small message cannot claim a huge one.
pub(crate) fn planes<'a>(
    field: &str,
    texture: &'a pb::ReliefTexture,
    sizes: [usize; 3],
) -> Result<[Cow<'a, [u8]>; 3], Status> {
    let invalid = |f: &str, problem: String| crate::convert::invalid(&format!("{field}.{f}"), problem);
    let compressed = match pb::PlaneEncoding::try_from(texture.encoding) {
        Ok(pb::PlaneEncoding::Raw) => false,
        Ok(pb::PlaneEncoding::Zstd) => true,
        Err(_) => {
            return Err(invalid(
                "encoding",
                format!("{} is not RAW or ZSTD", texture.encoding),
            ));
        }
    };
    let plane = |f: &str, bytes: &'a Bytes, size: usize| -> Result<Cow<'a, [u8]>, Status> {
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
        Ok(bytes)
    };
    Ok([
        plane("albedo", &texture.albedo, sizes[0])?,
        plane("normal", &texture.normal, sizes[1])?,
        plane("depth", &texture.depth, sizes[2])?,
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
            assert_eq!(small.encoding, pb::PlaneEncoding::Zstd as i32);
            assert!(small.albedo.len() < wire.albedo.len() / 2);
            assert!(small.depth.len() < wire.depth.len() / 2);
            assert_eq!(texture_from_pb("texture", &small).unwrap(), t);
            assert_eq!(raw("texture", &small).unwrap(), wire);
            assert_eq!(compressed(small.clone()), small, "compressed once only");
        }
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
