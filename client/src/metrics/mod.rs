//! Measuring error: image comparison against the ray-traced reference, Schaufler's
//! sprite and resolution tests, and the critical-point warp-error prediction.

pub mod critical;
pub mod image;
pub mod schaufler;
