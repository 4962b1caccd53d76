//! Eight-lane helpers: loads of eight from an array, lane masks, table gathers, a
//! packed texel's fields, and eight attribute blends at once.

use wide::bytemuck::cast;
use wide::{f32x8, i16x8, u8x16, u16x16, u32x8, u64x4};

use super::LANES;

/// Bit `l` of the result is whether `bytes[l]` has `flag`: the eight bytes as one word,
/// each reduced to its flag's bit, gathered into the top byte by one multiply (each
/// product term lands on a bit of its own, so nothing carries).
#[inline(always)]
pub(super) fn lane_bits(bytes: &[u8], flag: u8) -> u32 {
    let Some(bytes) = bytes.first_chunk::<8>() else {
        return 0;
    };
    let word = u64::from_le_bytes(*bytes);
    let ones = (word >> flag.trailing_zeros()) & 0x0101_0101_0101_0101;
    (ones.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32
}

/// The eight values from `at`, or zeros past the end.
#[inline(always)]
pub(super) fn eight<T: Copy + Default>(values: &[T], at: usize) -> [T; LANES] {
    values
        .get(at..)
        .and_then(|rest| rest.first_chunk::<LANES>())
        .copied()
        .unwrap_or_default()
}

#[inline(always)]
pub(super) fn load(values: &[f32], at: usize) -> f32x8 {
    f32x8::from(eight(values, at))
}

#[inline(always)]
pub(super) fn load_u32(values: &[u32], at: usize) -> u32x8 {
    u32x8::from(eight(values, at))
}

/// Lane `l` of the result is lane `order[l]` of `x` (each index below eight).
#[inline(always)]
pub(super) fn permute(x: f32x8, order: u32x8) -> f32x8 {
    cast::<u32x8, f32x8>(cast::<f32x8, u32x8>(x).shuffle(order))
}

/// All ones in the four 64-bit lanes whose bit is set in `bits`'s low four.
#[inline(always)]
pub(super) fn wide_mask(bits: u32) -> u64x4 {
    let each = u64x4::from([1, 2, 4, 8]);
    (u64x4::splat(u64::from(bits)) & each).simd_eq(each)
}

pub(super) use relief_core::shading::lane_mask;

/// [`Attributes::lerp`](crate::warp::prewarp::Attributes::lerp) of eight pairs at once, `a[l]` towards `b[l]` by `t[l] ∈ [0,
/// 1]` (each weight rounded as there): two texels' bytes to a vector of sixteen
/// 16-bit lanes, the same arithmetic, the same bytes.
#[inline(always)]
pub(crate) fn lerp_attributes(a: &[u64; LANES], b: &[u64; LANES], t: f32x8) -> [u64; LANES] {
    // (`round_small(t·256).min(256)`, eight at once: the sum's low mantissa bits are
    // the rounded integer; NaN's bits give 256, as there.)
    let rounded = cast::<f32x8, u32x8>(t * f32x8::splat(256.0) + f32x8::splat(8_388_608.0));
    let weight = (rounded & u32x8::splat(0x7f_ffff)).min(u32x8::splat(256));
    // Each weight in both 16-bit halves of its lane.
    let weight = weight | (weight << 16u32);
    let mut mixed = [0u64; LANES];
    for pair in 0..LANES / 2 {
        let (l, m) = (2 * pair as u32, 2 * pair as u32 + 1);
        let t = cast::<u32x8, u16x16>(weight.shuffle(u32x8::from([l, l, l, l, m, m, m, m])));
        let bytes = |x: &[u64; LANES]| u16x16::from(cast::<[u64; 2], u8x16>([x[2 * pair], x[2 * pair + 1]]));
        let blended = (bytes(a) * (u16x16::splat(256) - t) + bytes(b) * t + u16x16::splat(128)) >> 8;
        let [low, high] = cast::<u16x16, [i16x8; 2]>(blended);
        let [first, second] = cast::<u8x16, [u64; 2]>(u8x16::narrow_i16x8(low, high));
        (mixed[2 * pair], mixed[2 * pair + 1]) = (first, second);
    }
    mixed
}

/// `values[index[l]]` for each lane; an index past the end reads the last value, or
/// zero from an empty table.
#[inline(always)]
pub(super) fn gather(values: &[f32], index: u32x8) -> f32x8 {
    let Some(last) = values.len().checked_sub(1) else {
        return f32x8::ZERO;
    };
    let index = index.min(u32x8::splat(last as u32));
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        use std::arch::x86_64::{__m256i, _mm256_i32gather_ps};
        let index: __m256i = cast(index);
        // SAFETY: every lane reads `values[index]`, each index clamped within `values`
        // (not empty); the gather only reads.
        cast(unsafe { _mm256_i32gather_ps::<4>(values.as_ptr(), index) })
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    f32x8::from(index.to_array().map(|i| values[i as usize]))
}

/// Bits `shift..shift + width` of each of eight words, one per lane.
#[inline(always)]
pub(crate) fn field(words: &[u64; LANES], shift: u32, width: u32) -> u32x8 {
    let [low, high] = cast::<[u64; LANES], [u64x4; 2]>(*words);
    let mask = u64x4::splat((1 << width) - 1);
    // `low`'s in the even 32-bit lanes, `high`'s in the odd; then in order.
    let paired = cast::<u64x4, u32x8>(((low >> shift) & mask) | (((high >> shift) & mask) << 32));
    paired.shuffle(u32x8::from([0, 2, 4, 6, 1, 3, 5, 7]))
}

#[cfg(test)]
mod tests {
    /// Eight blends at once give each pair the bytes [`Attributes::lerp`] gives it,
    /// with the same rounded weight: at the ends, at ties between weights, at NaN, and
    /// at random bytes and weights.
    #[test]
    fn eight_attribute_blends_equal_one_at_a_time() {
        use super::lerp_attributes;
        use crate::warp::prewarp::Attributes;
        use crate::warp::round_small;
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        let special = [
            0.0,
            1.0,
            0.5 / 256.0,
            1.5 / 256.0,
            127.5 / 256.0,
            255.5 / 256.0,
            f32::NAN,
            1e-9,
        ];
        for round in 0..200 {
            let a: [u64; 8] = std::array::from_fn(|_| next());
            let b: [u64; 8] = std::array::from_fn(|_| next());
            let t: [f32; 8] = if round == 0 {
                special
            } else {
                std::array::from_fn(|_| (next() % 100_001) as f32 / 100_000.0)
            };
            let blended = lerp_attributes(&a, &b, wide::f32x8::from(t));
            for l in 0..8 {
                let weight = round_small(t[l] * 256.0).min(256) as u64;
                let one = Attributes(a[l]).lerp(Attributes(b[l]), weight);
                assert_eq!(
                    (Attributes(blended[l]).albedo(), Attributes(blended[l]).normal()),
                    (one.albedo(), one.normal()),
                    "t {}",
                    t[l]
                );
            }
        }
    }
}
