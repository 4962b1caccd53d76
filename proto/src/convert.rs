//! Checked conversions between wire messages and core types. Every error is a
//! `tonic::Status` with code INVALID_ARGUMENT that names the offending field.

use std::borrow::Cow;

use glam::Vec3;
use tonic::Status;

use relief_core::hash::ContentHash;
use relief_core::relief::{
    DepthBits, Hidden, HiddenError, MAX_TEXTURE_SIZE, ReliefTexture, SourceCamera, SourceProjection,
    TEXEL_SIDES, check_hidden,
};

use crate::pb;
use crate::planes::{PlaneLayout, Planes, ReadsPlanes, planes};

pub(crate) fn invalid(field: &str, problem: impl std::fmt::Display) -> Status {
    Status::invalid_argument(format!("field `{field}`: {problem}"))
}

/// A core vector as a wire vector.
pub fn vec3_to_pb(v: Vec3) -> pb::Vec3 {
    pb::Vec3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

/// A wire vector as a core vector: present and finite.
pub fn vec3_from_pb(field: &str, v: Option<&pb::Vec3>) -> Result<Vec3, Status> {
    let v = v.ok_or_else(|| invalid(field, "missing"))?;
    for (axis, value) in [("x", v.x), ("y", v.y), ("z", v.z)] {
        if !value.is_finite() {
            return Err(invalid(
                &format!("{field}.{axis}"),
                format_args!("{value} is not finite"),
            ));
        }
    }
    Ok(Vec3::new(v.x, v.y, v.z))
}

/// A content hash from 64 hex digits.
pub fn hash_from_pb(field: &str, text: &str) -> Result<ContentHash, Status> {
    ContentHash::from_hex(text).ok_or_else(|| invalid(field, format_args!("`{text}` is not 64 hex digits")))
}

/// Depth precision from its bit count.
pub fn depth_bits_from_pb(field: &str, bits: u32) -> Result<DepthBits, Status> {
    DepthBits::from_bits(bits).map_err(|_| invalid(field, format_args!("{bits} is not 8 or 16")))
}

/// A texture edge: `1 ..= MAX_TEXTURE_SIZE`.
pub fn size_from_pb(field: &str, size: u32) -> Result<u32, Status> {
    if size == 0 || size > MAX_TEXTURE_SIZE {
        return Err(invalid(
            field,
            format_args!("{size} is not in 1..={MAX_TEXTURE_SIZE}"),
        ));
    }
    Ok(size)
}

/// Most jobs a worker may bake at once (`Register.slots`).
pub const MAX_WORKER_SLOTS: u32 = 64;

/// Longest worker name (`Register.name`), bytes.
pub const MAX_WORKER_NAME_BYTES: usize = 256;

/// A worker's registration: `1 ..= MAX_WORKER_SLOTS` slots, a name of at most
/// [`MAX_WORKER_NAME_BYTES`].
pub fn check_register(r: &pb::Register) -> Result<(), Status> {
    if !(1..=MAX_WORKER_SLOTS).contains(&r.slots) {
        return Err(invalid(
            "register.slots",
            format_args!("{} is not between 1 and {MAX_WORKER_SLOTS}", r.slots),
        ));
    }
    if r.name.len() > MAX_WORKER_NAME_BYTES {
        return Err(invalid(
            "register.name",
            format_args!("longer than {MAX_WORKER_NAME_BYTES} bytes"),
        ));
    }
    Ok(())
}

/// A relief texture on the wire.
pub fn texture_to_pb(t: &ReliefTexture) -> pb::ReliefTexture {
    let c = &t.camera;
    let depth = match t.depth_bits {
        DepthBits::Eight => t.depth.iter().map(|&q| q as u8).collect(),
        DepthBits::Sixteen => t.depth.iter().flat_map(|q| q.to_le_bytes()).collect(),
    };
    pb::ReliefTexture {
        width: c.width,
        height: c.height,
        origin: Some(vec3_to_pb(c.origin)),
        a: Some(vec3_to_pb(c.a)),
        b: Some(vec3_to_pb(c.b)),
        f: Some(vec3_to_pb(c.f)),
        depth_near: c.depth_near,
        depth_far: c.depth_far,
        depth_bits: t.depth_bits.bits(),
        eye: Some(vec3_to_pb(t.eye)),
        centre: c.centre.map(vec3_to_pb),
        albedo: t.albedo.iter().flatten().copied().collect(),
        normal: t.normal.iter().flatten().copied().collect(),
        depth,
        encoding: pb::PlaneEncoding::Raw.into(),
        hidden_texels: t.hidden.iter().map(|h| h.texel).collect(),
        hidden_sides: t.hidden.iter().map(|h| u32::from(h.side)).collect(),
        hidden_inward: t.hidden.iter().map(|h| u32::from(h.inward)).collect(),
        hidden_depths: t.hidden.iter().map(|h| u32::from(h.depth)).collect(),
    }
}

/// A relief texture from the wire, every field checked (its planes raw or compressed:
/// see [`planes`](crate::planes)). `field` prefixes the names in errors (e.g.
/// `texture`).
pub fn texture_from_pb(field: &str, t: &pb::ReliefTexture) -> Result<ReliefTexture, Status> {
    let Checked {
        camera,
        depth_bits,
        eye,
        planes: [albedo, normal, depth_plane],
        depth,
        hidden,
    } = checked(field, t, Planes::Raw)?;
    // (Decoded once: by the check when a list of what the rim hides came with it.)
    let depth = depth.unwrap_or_else(|| depth_levels(&depth_plane, depth_bits));
    let triples = |bytes: &[u8]| bytes.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    Ok(ReliefTexture {
        camera,
        depth_bits,
        eye,
        albedo: triples(&albedo),
        normal: triples(&normal),
        depth,
        hidden,
    })
}

/// Every check of [`texture_from_pb`] without building the texture (for whoever only
/// passes it on): its camera, depth bits and eye, or the first bad field. Compressed
/// planes are decompressed to be checked (and dropped).
pub fn check_texture_pb(
    field: &str,
    t: &pb::ReliefTexture,
) -> Result<(SourceCamera, DepthBits, Vec3), Status> {
    let Checked {
        camera,
        depth_bits,
        eye,
        ..
    } = checked(field, t, Planes::Checked)?;
    Ok((camera, depth_bits, eye))
}

/// A texture from the wire, every field checked ([`checked`]).
pub(crate) struct Checked<'a> {
    pub(crate) camera: SourceCamera,
    pub(crate) depth_bits: DepthBits,
    pub(crate) eye: Vec3,
    /// Albedo, normal and depth as `wanted` ([`Planes`]): borrowed where they came raw,
    /// decompressed where they came compressed.
    pub(crate) planes: [Cow<'a, [u8]>; 3],
    /// The depth plane's levels, where a list of what the rim hides was checked against
    /// them (`planes` left that plane raw for it); `None` otherwise, as a server passing
    /// planes on has no use for them.
    pub(crate) depth: Option<Vec<u16>>,
    /// What the rim hides, checked against the depth plane.
    pub(crate) hidden: Vec<Hidden>,
}

/// Every field of `t` checked, its planes as `wanted`.
pub(crate) fn checked<'a>(
    field: &str,
    t: &'a pb::ReliefTexture,
    wanted: Planes,
) -> Result<Checked<'a>, Status> {
    let (camera, depth_bits, eye) = check_header(field, t)?;
    let layout = PlaneLayout::new(camera.width, camera.height, depth_bits);
    let planes = planes(field, t, layout, wanted)?;
    // (Without texels, the lists need no levels: any other list not empty is refused
    // for its length.)
    let depth = (!t.hidden_texels.is_empty()).then(|| depth_levels(&planes[2], depth_bits));
    let levels = depth.as_deref().unwrap_or_default();
    let hidden = hidden_from_pb(field, t, camera.width, levels, depth_bits)?;
    Ok(Checked {
        camera,
        depth_bits,
        eye,
        planes,
        depth,
        hidden,
    })
}

/// The levels of a raw depth plane of `bits`.
fn depth_levels(plane: &[u8], bits: DepthBits) -> Vec<u16> {
    match bits {
        DepthBits::Eight => plane.iter().map(|&q| u16::from(q)).collect(),
        DepthBits::Sixteen => plane
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect(),
    }
}

/// A texture's `hidden_*` lists, paired and checked against its depth levels
/// ([`check_hidden`]; `width` texels a row).
fn hidden_from_pb(
    field: &str,
    t: &pb::ReliefTexture,
    width: u32,
    depth: &[u16],
    bits: DepthBits,
) -> Result<Vec<Hidden>, Status> {
    let n = t.hidden_texels.len();
    // (At most one a side of each texel, in order: a longer list is refused before
    // anything is made of it.)
    let most = TEXEL_SIDES.len() * depth.len();
    if n > most {
        return Err(invalid(
            &format!("{field}.hidden_texels"),
            format_args!("{n} entries for {} texels, at most {most}", depth.len()),
        ));
    }
    for (list, len) in [
        ("hidden_sides", t.hidden_sides.len()),
        ("hidden_inward", t.hidden_inward.len()),
        ("hidden_depths", t.hidden_depths.len()),
    ] {
        if len != n {
            return Err(invalid(
                &format!("{field}.{list}"),
                format_args!("{len} entries for {n} hidden_texels"),
            ));
        }
    }
    fn narrow<T: TryFrom<u32>>(field: &str, list: &str, k: usize, value: u32) -> Result<T, Status> {
        T::try_from(value).map_err(|_| {
            invalid(
                &format!("{field}.{list}[{k}]"),
                format_args!("{value} is out of range"),
            )
        })
    }
    let hidden = (0..n)
        .map(|k| {
            Ok(Hidden {
                texel: t.hidden_texels[k],
                side: narrow(field, "hidden_sides", k, t.hidden_sides[k])?,
                inward: narrow(field, "hidden_inward", k, t.hidden_inward[k])?,
                depth: narrow(field, "hidden_depths", k, t.hidden_depths[k])?,
            })
        })
        .collect::<Result<Vec<_>, Status>>()?;
    check_hidden(&hidden, width, depth, bits).map_err(|e| {
        // (Each fault named by the list it is in.)
        let (list, index) = match e {
            HiddenError::Unordered { index, .. }
            | HiddenError::PastTheEnd { index, .. }
            | HiddenError::Empty { index, .. } => ("hidden_texels", index),
            HiddenError::NoSuchSide { index, .. } => ("hidden_sides", index),
            HiddenError::Outside { index, .. } => ("hidden_inward", index),
            HiddenError::NotBehind { index, .. } | HiddenError::NotALevel { index, .. } => {
                ("hidden_depths", index)
            }
        };
        invalid(&format!("{field}.{list}[{index}]"), e)
    })?;
    Ok(hidden)
}

/// A texture's fields but its planes, checked: its camera, depth bits and eye.
fn check_header(field: &str, t: &pb::ReliefTexture) -> Result<(SourceCamera, DepthBits, Vec3), Status> {
    let name = |f: &str| format!("{field}.{f}");
    let width = size_from_pb(&name("width"), t.width)?;
    let height = size_from_pb(&name("height"), t.height)?;
    let depth_bits = depth_bits_from_pb(&name("depth_bits"), t.depth_bits)?;
    let camera = SourceCamera {
        width,
        height,
        origin: vec3_from_pb(&name("origin"), t.origin.as_ref())?,
        a: vec3_from_pb(&name("a"), t.a.as_ref())?,
        b: vec3_from_pb(&name("b"), t.b.as_ref())?,
        f: vec3_from_pb(&name("f"), t.f.as_ref())?,
        depth_near: t.depth_near,
        depth_far: t.depth_far,
        centre: t
            .centre
            .as_ref()
            .map(|c| vec3_from_pb(&name("centre"), Some(c)))
            .transpose()?,
    };
    if !(t.depth_near.is_finite() && t.depth_far.is_finite() && t.depth_far > t.depth_near) {
        return Err(invalid(
            &name("depth_far"),
            "depth range must be finite with far > near",
        ));
    }
    if !camera.centre_in_front() {
        return Err(invalid(&name("centre"), "not in front of the image plane"));
    }
    let eye = vec3_from_pb(&name("eye"), t.eye.as_ref())?;
    Ok((camera, depth_bits, eye))
}

/// How soon a request is needed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Urgency {
    Now,
    /// Expected to be needed this many milliseconds from now.
    Predicted {
        in_ms: u64,
    },
}

/// A validated impostor request.
#[derive(Debug, Clone, PartialEq)]
pub struct Request {
    pub scene: ContentHash,
    pub object: String,
    pub eye: Vec3,
    pub size: u32,
    pub depth_bits: DepthBits,
    pub urgency: Urgency,
    pub client_id: String,
    pub request_id: u64,
    pub progressive: bool,
    pub projection: SourceProjection,
    /// How near another eye must be for its texture to serve this request, as a
    /// fraction of `eye`'s distance from the object's centre (0: this eye only).
    pub serve_within: f32,
    /// The compressed planes the client reads (see [`planes`](crate::planes)).
    pub reads_planes: ReadsPlanes,
}

/// The projection a request or job asks for.
pub fn projection_from_pb(field: &str, value: i32) -> Result<SourceProjection, Status> {
    match pb::SourceProjection::try_from(value) {
        Ok(pb::SourceProjection::Orthographic) => Ok(SourceProjection::Orthographic),
        Ok(pb::SourceProjection::Perspective) => Ok(SourceProjection::Perspective),
        Err(_) => Err(invalid(
            field,
            format_args!("{value} is not ORTHOGRAPHIC or PERSPECTIVE"),
        )),
    }
}

/// A projection on the wire.
pub fn projection_to_pb(projection: SourceProjection) -> pb::SourceProjection {
    match projection {
        SourceProjection::Orthographic => pb::SourceProjection::Orthographic,
        SourceProjection::Perspective => pb::SourceProjection::Perspective,
    }
}

/// A `client_id` is not empty and at most
/// [`MAX_CLIENT_ID_BYTES`](crate::limits::MAX_CLIENT_ID_BYTES) long.
pub fn check_client_id(id: &str) -> Result<(), Status> {
    if id.is_empty() {
        return Err(invalid("client_id", "empty"));
    }
    if id.len() > crate::limits::MAX_CLIENT_ID_BYTES {
        return Err(invalid(
            "client_id",
            format_args!(
                "{} bytes, at most {}",
                id.len(),
                crate::limits::MAX_CLIENT_ID_BYTES
            ),
        ));
    }
    Ok(())
}

/// Checks every field of an impostor request.
pub fn request_from_pb(r: &pb::ImpostorRequest) -> Result<Request, Status> {
    if r.object.is_empty() {
        return Err(invalid("object", "empty"));
    }
    check_client_id(&r.client_id)?;
    let urgency = match pb::Urgency::try_from(r.urgency) {
        Ok(pb::Urgency::Now) => Urgency::Now,
        Ok(pb::Urgency::Predicted) => Urgency::Predicted {
            in_ms: r.needed_in_ms,
        },
        _ => {
            return Err(invalid(
                "urgency",
                format_args!("{} is not NOW or PREDICTED", r.urgency),
            ));
        }
    };
    Ok(Request {
        scene: hash_from_pb("scene_hash", &r.scene_hash)?,
        object: r.object.clone(),
        eye: vec3_from_pb("eye", r.eye.as_ref())?,
        size: size_from_pb("size", r.size)?,
        depth_bits: depth_bits_from_pb("depth_bits", r.depth_bits)?,
        urgency,
        client_id: r.client_id.clone(),
        request_id: r.request_id,
        progressive: r.progressive,
        projection: projection_from_pb("projection", r.projection)?,
        serve_within: serve_within_from_pb(r.serve_within)?,
        reads_planes: ReadsPlanes {
            zstd: r.zstd_planes,
            zstd_delta: r.zstd_delta_planes,
        },
    })
}

/// A request's `serve_within`: finite, from 0 to
/// [`MAX_SERVE_WITHIN`](crate::limits::MAX_SERVE_WITHIN).
fn serve_within_from_pb(value: f32) -> Result<f32, Status> {
    let max = crate::limits::MAX_SERVE_WITHIN;
    if (0.0..=max).contains(&value) {
        Ok(value)
    } else {
        Err(invalid(
            "serve_within",
            format_args!("{value} is not within 0..={max}"),
        ))
    }
}

/// The content hash of an encoded scene bundle.
pub fn bundle_hash(encoded: &[u8]) -> ContentHash {
    let mut h = blake3::Hasher::new();
    h.update(b"relief-scene-v1");
    h.update(encoded);
    ContentHash(*h.finalize().as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use relief_core::bounds::Aabb;

    #[test]
    fn textures_round_trip_and_bad_fields_are_named() {
        for bits in [DepthBits::Eight, DepthBits::Sixteen] {
            let bounds = Aabb {
                min: Vec3::splat(-1.0),
                max: Vec3::splat(1.0),
            };
            let eye = Vec3::new(0.5, 1.0, 4.0);
            let mut t = ReliefTexture::empty(
                SourceCamera::facing(eye, &bounds, 5, 3, SourceProjection::Orthographic).unwrap(),
                bits,
                eye,
            );
            t.depth[2] = 200;
            t.albedo[2] = [1, 2, 3];
            t.normal[7] = [9, 8, 7];
            let wire = texture_to_pb(&t);
            assert_eq!(texture_from_pb("texture", &wire).unwrap(), t);
            let mut bad = wire.clone();
            bad.albedo.truncate(bad.albedo.len() - 1);
            let e = texture_from_pb("texture", &bad).unwrap_err();
            assert_eq!(e.code(), tonic::Code::InvalidArgument);
            assert!(e.message().contains("texture.albedo"), "{}", e.message());
            let mut bad = wire.clone();
            bad.origin = Some(pb::Vec3 {
                x: 0.0,
                y: f32::NAN,
                z: 0.0,
            });
            assert!(
                texture_from_pb("texture", &bad)
                    .unwrap_err()
                    .message()
                    .contains("texture.origin.y")
            );
        }
    }

    /// What a rim hides travels with its texture, compressed planes or not; each way
    /// the lists can be wrong is refused, naming the list and entry at fault, by the
    /// client and by a server that only checks what it passes on (its depth plane
    /// predicted, as a worker sends a smooth one).
    #[test]
    fn hidden_surfaces_round_trip_and_bad_lists_are_named() {
        let bounds = Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        };
        let eye = Vec3::new(0.5, 1.0, 4.0);
        let camera = SourceCamera::facing(eye, &bounds, 6, 4, SourceProjection::Orthographic).unwrap();
        let mut t = ReliefTexture::empty(camera, DepthBits::Sixteen, eye);
        for (k, depth) in t.depth.iter_mut().enumerate() {
            *depth = 300 + k as u16;
        }
        let hidden = |texel, side, inward, depth| Hidden {
            texel,
            side,
            inward,
            depth,
        };
        t.hidden = vec![hidden(7, 0, 2, 900), hidden(7, 2, 1, 800), hidden(10, 1, 3, 700)];
        t.check_hidden().unwrap();
        let wire = texture_to_pb(&t);
        assert_eq!(texture_from_pb("texture", &wire).unwrap(), t);
        let small = crate::planes::compressed(wire.clone());
        assert_eq!(
            small.encoding,
            pb::PlaneEncoding::ZstdDelta as i32,
            "a ramp predicts well"
        );
        assert_eq!(texture_from_pb("texture", &small).unwrap(), t);
        assert!(check_texture_pb("texture", &small).is_ok());
        // (Each bad message, and the list and entry its error names.)
        type Spoil = fn(&mut pb::ReliefTexture);
        let cases: [(&str, Spoil, &str); 9] = [
            (
                "a list short",
                |w| w.hidden_sides.truncate(2),
                "texture.hidden_sides",
            ),
            (
                "lists without texels",
                |w| w.hidden_texels.clear(),
                "texture.hidden_sides",
            ),
            (
                "too many",
                |w| {
                    let n = 4 * 24 + 1;
                    w.hidden_texels = (0..n).collect();
                    w.hidden_sides = vec![0; n as usize];
                    w.hidden_inward = vec![0; n as usize];
                    w.hidden_depths = vec![0; n as usize];
                },
                "texture.hidden_texels",
            ),
            (
                "out of order",
                |w| w.hidden_texels.swap(1, 2),
                "texture.hidden_texels[2]",
            ),
            (
                "past the last texel",
                |w| w.hidden_texels[2] = 24,
                "texture.hidden_texels[2]",
            ),
            (
                "a fifth side",
                |w| w.hidden_sides[0] = 4,
                "texture.hidden_sides[0]",
            ),
            (
                "a depth past 16 bits",
                |w| w.hidden_depths[0] = 70_000,
                "texture.hidden_depths[0]",
            ),
            (
                "in front of the rim",
                |w| w.hidden_depths[1] = 300,
                "texture.hidden_depths[1]",
            ),
            (
                "stepping off the texture",
                |w| w.hidden_inward[0] = 2 + 6,
                "texture.hidden_inward[0]",
            ),
        ];
        for (what, spoil, field) in cases {
            for (encoding, message) in [("raw", &wire), ("predicted", &small)] {
                let mut bad = message.clone();
                spoil(&mut bad);
                let e = texture_from_pb("texture", &bad).unwrap_err();
                assert_eq!(e.code(), tonic::Code::InvalidArgument, "{what}, {encoding}");
                assert!(e.message().contains(field), "{what}, {encoding}: {}", e.message());
                let e = check_texture_pb("texture", &bad).unwrap_err();
                assert!(e.message().contains(field), "{what}, {encoding}: {}", e.message());
            }
        }
    }

    #[test]
    fn requests_are_checked_field_by_field() {
        let good = pb::ImpostorRequest {
            scene_hash: "ab".repeat(32),
            object: "knot".into(),
            eye: Some(pb::Vec3 {
                x: 1.0,
                y: 2.0,
                z: 3.0,
            }),
            size: 256,
            depth_bits: 8,
            urgency: pb::Urgency::Now as i32,
            needed_in_ms: 0,
            client_id: "c".into(),
            request_id: 7,
            progressive: false,
            projection: pb::SourceProjection::Perspective.into(),
            serve_within: 0.05,
            zstd_planes: true,
            zstd_delta_planes: true,
        };
        assert_eq!(
            request_from_pb(&good).unwrap().projection,
            SourceProjection::Perspective
        );
        let field_of = |r: pb::ImpostorRequest| request_from_pb(&r).unwrap_err().message().to_string();
        assert!(
            field_of(pb::ImpostorRequest {
                projection: 7,
                ..good.clone()
            })
            .contains("projection")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                eye: Some(pb::Vec3 {
                    x: f32::NAN,
                    y: 0.0,
                    z: 0.0
                }),
                ..good.clone()
            })
            .contains("`eye.x`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                eye: None,
                ..good.clone()
            })
            .contains("`eye`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                size: 0,
                ..good.clone()
            })
            .contains("`size`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                depth_bits: 12,
                ..good.clone()
            })
            .contains("`depth_bits`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                scene_hash: "xyz".into(),
                ..good.clone()
            })
            .contains("`scene_hash`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                urgency: 0,
                ..good.clone()
            })
            .contains("`urgency`")
        );
        assert!(
            field_of(pb::ImpostorRequest {
                object: String::new(),
                ..good.clone()
            })
            .contains("`object`")
        );
        for serve_within in [f32::NAN, -0.01, 0.6, f32::INFINITY] {
            assert!(
                field_of(pb::ImpostorRequest {
                    serve_within,
                    ..good.clone()
                })
                .contains("`serve_within`")
            );
        }
    }
}
