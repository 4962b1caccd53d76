//! A pre-warped texel ([`PTexel`]), and a texel's attribute bytes packed for blending
//! ([`Attributes`]) with what the row pass reads of it ([`pack_texel`]).

use glam::Vec3;
use wide::bytemuck::cast;
use wide::{i16x8, u8x16, u16x8, u64x2};

use super::lanes::{DOWN_LINK, RIGHT_LINK};
use crate::EMPTY_DEPTH;

/// A pre-warped texel; [`EMPTY_DEPTH`] marks an empty one. (`repr(C)`: the texture
/// mapping gathers eight texels' depths, and their attribute words, by offset.)
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(C)]
pub struct PTexel {
    /// Displacement along `f` of the surface seen here.
    pub depth: f32,
    /// Albedo and encoded normal, packed for blending.
    pub(crate) attributes: Attributes,
}

// The layout the texture mapping's gathers read: the depth first, the attribute word at
// byte 8 of 16.
const _: () = assert!(
    std::mem::offset_of!(PTexel, depth) == 0
        && std::mem::offset_of!(PTexel, attributes) == 8
        && std::mem::size_of::<PTexel>() == 16
);

impl PTexel {
    pub const EMPTY: PTexel = PTexel {
        depth: EMPTY_DEPTH,
        attributes: Attributes(0),
    };

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.depth == EMPTY_DEPTH
    }
}

/// A texel's albedo and encoded normal: six bytes in the low bytes of a `u64`, so one
/// interpolation blends all six at once (two multiplies on a vector of 16-bit lanes;
/// see [`Attributes::lerp`]). The top two
/// bytes are not read; a source texel keeps its depth's table entry and links there
/// (see [`pack_texel`]).
#[derive(Debug, Clone, Copy, PartialEq)]
#[repr(transparent)]
pub(crate) struct Attributes(pub(crate) u64);

/// Where a packed texel's encoded normal starts ([`pack_texel`]): its three bytes follow
/// the albedo's.
pub(crate) const NORMAL_SHIFT: u32 = 24;
/// Where a packed texel's table entry starts ([`pack_texel`]).
pub(super) const ENTRY_SHIFT: u32 = 48;
/// The bits a table entry may take: entries reach
/// [`WarpLevels::empty`](crate::warp::params::WarpLevels::empty), at most 4,096.
pub(super) const ENTRY_MASK: u64 = (1 << 13) - 1;
/// A packed texel's links sit at its row-pass flags ([`RIGHT_LINK`], [`DOWN_LINK`])
/// shifted up by this, above its table entry.
const LINKS_SHIFT: u32 = 60;

// The packed layout holds: the largest table entry fits its bits, which end where the
// links begin, and the links fit the word.
const _: () = assert!(1 << crate::warp::params::WARP_LEVEL_BITS <= ENTRY_MASK);
const _: () = assert!(ENTRY_SHIFT + ENTRY_MASK.count_ones() <= LINKS_SHIFT + RIGHT_LINK.trailing_zeros());
const _: () = assert!(LINKS_SHIFT + DOWN_LINK.ilog2() < 64);

/// A texel as the pre-warp reads it
/// ([`Impostor::packed`](crate::impostor::Impostor::packed)): albedo and encoded
/// normal in the low six bytes, as [`Attributes`]; above them the table entry of its
/// depth level ([`WarpLevels::entry`](crate::warp::params::WarpLevels::entry)), and
/// its links to the right and downwards — all the row pass reads of a texel, in one
/// load.
pub(crate) fn pack_texel(albedo: [u8; 3], normal: [u8; 3], entry: u16, right: bool, down: bool) -> u64 {
    let ([r, g, b], [x, y, z]) = (albedo, normal);
    let links = u8::from(right) * RIGHT_LINK + u8::from(down) * DOWN_LINK;
    debug_assert!(u64::from(entry) <= ENTRY_MASK, "table entry {entry}");
    u64::from_le_bytes([r, g, b, x, y, z, 0, 0])
        | (u64::from(entry) & ENTRY_MASK) << ENTRY_SHIFT
        | u64::from(links) << LINKS_SHIFT
}

/// The depth's table entry of a [`pack_texel`] texel.
#[inline(always)]
pub(super) fn entry_of(texel: u64) -> u16 {
    ((texel >> ENTRY_SHIFT) & ENTRY_MASK) as u16
}

/// The row pass's link flags of a [`pack_texel`] texel.
#[inline(always)]
pub(super) fn links_of(texel: u64) -> u8 {
    (texel >> LINKS_SHIFT) as u8 & (RIGHT_LINK | DOWN_LINK)
}

/// The eight bytes of `x`, each in a 16-bit lane.
#[inline(always)]
fn widen(x: u64) -> u16x8 {
    // (`splat`, one register move: `new([x, 0])` went through memory and stalled,
    // its two 8-byte stores read back as one 16-byte load. Only the low half is read.)
    u16x8::from_u8x16_low(cast::<u64x2, u8x16>(u64x2::splat(x)))
}

/// The inverse of [`widen`] for lanes below 256.
#[inline(always)]
fn narrow(lanes: u16x8) -> u64 {
    let signed = cast::<u16x8, i16x8>(lanes);
    cast::<u8x16, u64x2>(u8x16::narrow_i16x8(signed, signed)).to_array()[0]
}

impl Attributes {
    /// `self + (other − self)·t/256` per byte, rounded, `t ∈ [0, 256]`: every byte
    /// widened to a 16-bit lane of one vector, where `a·(256 − t) + b·t + 128 ≤
    /// 255·256 + 128` fits. (Eight bytes at once: the two unread ones blend along.)
    #[inline(always)]
    pub(crate) fn lerp(self, other: Attributes, t: u64) -> Attributes {
        let t = u16x8::splat(t as u16);
        let mixed = (widen(self.0) * (u16x8::splat(256) - t) + widen(other.0) * t + u16x8::splat(128)) >> 8;
        Attributes(narrow(mixed))
    }

    #[inline(always)]
    pub(super) fn texel(self, depth: f32) -> PTexel {
        PTexel {
            depth,
            attributes: self,
        }
    }

    #[inline(always)]
    pub(crate) fn albedo(self) -> [u8; 3] {
        let [r, g, b, ..] = self.0.to_le_bytes();
        [r, g, b]
    }

    #[inline(always)]
    pub(crate) fn normal(self) -> [u8; 3] {
        let [_, _, _, x, y, z, ..] = self.0.to_le_bytes();
        [x, y, z]
    }

    /// The encoded normal's direction, not of unit length: encoded `n·127.5 + 127.5`, it
    /// is `n·127.5`, and the direction is all its tests need.
    #[inline(always)]
    pub(super) fn normal_direction(self) -> Vec3 {
        let [x, y, z] = self.normal();
        Vec3::new(x as f32, y as f32, z as f32) - Vec3::splat(127.5)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::impostor::Impostor;

    /// A packed texel gives back its table entry, its links and its attribute bytes,
    /// for the entries' extremes (the 16-bit empty entry the largest); and a baked
    /// impostor's packed words hold its texels' links.
    #[test]
    fn packed_texels_unpack_whole() {
        for entry in [0u16, 1, 254, 255, 4095, 4096] {
            for (right, down) in [(false, false), (true, false), (false, true), (true, true)] {
                let (albedo, normal) = ([255, 1, 128], [0, 254, 77]);
                let texel = pack_texel(albedo, normal, entry, right, down);
                let links = u8::from(right) * RIGHT_LINK + u8::from(down) * DOWN_LINK;
                assert_eq!(
                    (entry_of(texel), links_of(texel)),
                    (entry, links),
                    "{entry} {right} {down}"
                );
                let attributes = Attributes(texel);
                assert_eq!((attributes.albedo(), attributes.normal()), (albedo, normal));
            }
        }
        let impostor = Impostor::new(crate::fixtures::square_over_plane(16, 4..9, ([0, 255, 0], 40)));
        let levels = crate::warp::params::WarpLevels::new(impostor.texture.depth_bits);
        for (k, &texel) in impostor.packed.iter().enumerate() {
            let links = u8::from(impostor.right[k]) * RIGHT_LINK + u8::from(impostor.down[k]) * DOWN_LINK;
            assert_eq!(links_of(texel), links, "texel {k}");
            assert_eq!(
                entry_of(texel),
                levels.entry(impostor.texture.depth[k]),
                "texel {k}"
            );
        }
        assert!(impostor.right.iter().any(|&r| r) && impostor.right.iter().any(|&r| !r));
    }

    /// The packed lerp rounds each byte to nearest, ends exact, on all six lanes.
    #[test]
    fn attribute_lerp_rounds_each_byte() {
        let (a, b) = ([0u8, 10, 255, 100, 3, 254], [255u8, 11, 0, 100, 4, 1]);
        let pack = |v: [u8; 6]| {
            Attributes(pack_texel(
                [v[0], v[1], v[2]],
                [v[3], v[4], v[5]],
                0,
                false,
                false,
            ))
        };
        for t in [0u64, 1, 77, 128, 200, 255, 256] {
            let got = pack(a).lerp(pack(b), t);
            let bytes: Vec<u8> = got.albedo().into_iter().chain(got.normal()).collect();
            let expected: Vec<u8> = a
                .iter()
                .zip(b)
                .map(|(&a, b)| ((a as f64 * (256 - t) as f64 + b as f64 * t as f64) / 256.0).round() as u8)
                .collect();
            assert_eq!(bytes, expected, "t = {t}");
        }
    }
}
