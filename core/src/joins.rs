//! When two samples of a relief texture are one surface: the rule the client's impostor
//! joins neighbouring texels by (and fills between them), and the bake's rim rays keep
//! a hit by.
//!
//! A surface with normal `n`, seen along `f`, rises `|n·axis| / |n·f|` of depth per unit
//! moved along `axis` in the image plane ([`slope_along`]), capped at [`MAX_SLOPE`]. Two
//! samples `step` apart are joined when their depths differ by no more than the steeper
//! of their slopes allows, with [`SLOPE_SLACK`] for the bend between them, a step's
//! worth more, and two depth quanta for rounding ([`join_reach`]). (A rim ray's hit has
//! no normal of the texture's: the rim texel's own slope stands for both.)

use glam::Vec3;

/// Slack on the slope test: a surface may bend this much within one texel. (Towards a
/// rim its slope grows: on a sphere, the step to the outline from a texel's centre is
/// twice what the centre's slope alone gives.)
pub const SLOPE_SLACK: f32 = 2.0;

/// The steepest a surface is taken to run between samples: this many units of depth per
/// unit across. A grazing normal says "any step"; past this the step is counted as steep
/// as this, and joins only within [`join_reach`] of it: 49 texels of depth a texel
/// across.
pub const MAX_SLOPE: f32 = 24.0;

/// Depth change per unit move along unit `axis` (in the image plane) of a surface with
/// normal `n` seen along unit `f`, capped at [`MAX_SLOPE`].
#[inline]
pub fn slope_along(n: Vec3, axis: Vec3, f: Vec3) -> f32 {
    let facing = n.dot(f).abs();
    if facing < 1e-6 {
        MAX_SLOPE
    } else {
        (n.dot(axis).abs() / facing).min(MAX_SLOPE)
    }
}

/// The largest difference in depth at which two samples `step` apart (in depth's units),
/// the steeper of them rising `slope` ([`slope_along`]), are one surface; `quantum` is
/// depth's rounding.
#[inline]
pub fn join_reach(slope: f32, step: f32, quantum: f32) -> f32 {
    SLOPE_SLACK * step * slope + step + 2.0 * quantum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_plane_joins_what_its_slope_reaches() {
        // A plane tilted 45° about the b axis rises one unit per unit along a.
        let n = Vec3::new(1.0, 0.0, -1.0).normalize();
        let (a, b, f) = (Vec3::X, Vec3::Y, Vec3::Z);
        assert!((slope_along(n, a, f) - 1.0).abs() < 1e-6);
        assert_eq!(slope_along(n, b, f), 0.0);
        // Edge-on: as steep as anything is taken to be.
        assert_eq!(slope_along(Vec3::X, a, f), MAX_SLOPE);
        assert_eq!(join_reach(1.0, 0.5, 0.01), 2.0 * 0.5 + 0.5 + 0.02);
    }
}
