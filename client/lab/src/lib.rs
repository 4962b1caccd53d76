//! Relief's lab: every display method of the sources, and the measurements that
//! compare them — image error against the ray-traced reference, against run time — with
//! their reports and plots. What the thesis measured, kept runnable; the service itself
//! uses only the renderer's pre-warp.
//!
//! # Brief overview
//!
//! The principal type is [`Method`](methods::Method): a way of showing a relief texture
//! from a new eye, by name (`interleaved`, `forward-pullpush`, `inverse-64`, …), shown
//! with [`display`](methods::display). [`Solo`](solo::Solo) sets one object up alone on
//! an orbit — bake, reference, compare — and [`report`] runs every object × method ×
//! texture size × angle through it, timed.
//!
//! - [`methods`] — the display methods: the renderer's pre-warp variants, forward
//!   splatting with pull–push or a kernel, inverse ray marching, sprites.
//! - [`image_error`] — PSNR, SSIM and hole fraction against a reference frame.
//! - [`solo`] — one object alone: bake, reference, compare.
//! - [`frame_plan`] — a whole frame with every complex object an impostor baked
//!   locally, drawn with any method (`relief frame`).
//! - [`report`] — the error-against-run-time measurement and its pictures.
//! - [`plot`] — line charts and image strips as PNG.
//! - [`timing`] — the median (or best) wall time of repeated runs, after a warm-up.
//!
//! # Example
//!
//! The knot's texture shown 5° from where it was baked, with two methods, against the
//! ray-traced reference:
//!
//! ```
//! use relief_core::{relief::DepthBits, scene::Scene};
//! use relief_lab::{methods::{Method, display}, solo::Solo};
//! use relief_render::{gbuffer::GBuffer, impostor::Impostor};
//!
//! let scene = Scene::load("orbit-knot")?;
//! let solo = Solo::new(&scene, "knot", 3.0)?;
//! let impostor = Impostor::new(solo.bake(solo.eye(0.0), 128, DepthBits::Eight)?);
//! let camera = solo.camera(solo.eye(5.0), 128)?;
//! let reference = solo.reference(&camera, 1);
//! for method in [Method::Interleaved, Method::ForwardPullPush] {
//!     let mut gbuffer = GBuffer::new(128, 128);
//!     display(method, &impostor, 0, &camera, &mut gbuffer)?;
//!     let error = solo.error(&gbuffer.shade(&solo.scene, &camera), &reference);
//!     assert!(error.psnr_db > 20.0, "{method}: {error:?}");
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod frame_plan;
pub mod image_error;
pub mod methods;
pub mod plot;
pub mod report;
pub mod solo;
pub mod timing;
