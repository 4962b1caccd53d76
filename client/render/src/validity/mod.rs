//! How long an impostor stays right: the tests that decide when a relief texture may
//! still be shown, and how.
//!
//! - [`schaufler`] — Schaufler's sprite test (β_transP: may last frame's image be
//!   redrawn unchanged?) and the resolution test (eq. 4-1: are the texels small enough
//!   for the screen?), with eq. 5-1's resolution to ask for.
//! - [`critical`] — the critical-point error (eq. 5-3…5-7): the widest gap a warp to a
//!   new eye opens, predicted from the texture alone, per N×M region.
//! - [`rim`] — the band past a closed surface's outline that an eye turned from the
//!   texture's sees and the texture alone cannot show, from its rim's curvature.
//! - [`edges`] — how much the image changes where the texture's surfaces part: the
//!   squared colour steps across its edges between surfaces, per texel.

pub mod critical;
pub mod edges;
pub mod rim;
pub mod schaufler;
