//! What the manager and its texture source say to each other: requests and
//! withdrawals go out on one channel, textures and failures come back on another, so
//! the frame loop never waits.

use glam::Vec3;

use relief_core::relief::{DepthBits, SourceProjection};

use super::cache::ReadyTexture;

/// A texture the manager wants made.
#[derive(Debug, Clone, PartialEq)]
pub struct TextureRequest {
    pub id: u64,
    pub object: String,
    /// In the object's frame.
    pub eye: Vec3,
    pub size: u32,
    pub depth_bits: DepthBits,
    pub projection: SourceProjection,
    /// `None`: needed now; `Some(ms)`: expected to be needed in `ms`.
    pub needed_in_ms: Option<u64>,
    /// A texture made for an eye within this fraction of `eye`'s distance from the
    /// object's centre serves too (about radians of turn; 0: this eye only).
    pub serve_within: f32,
}

/// What the manager sends to whoever makes textures.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    Request(TextureRequest),
    Withdraw(Vec<u64>),
}

/// What comes back.
#[derive(Debug)]
pub enum Arrival {
    Texture {
        id: u64,
        /// Made ready where it arrived ([`ReadyTexture::new`]), not in the frame loop.
        texture: Box<ReadyTexture>,
        is_final: bool,
    },
    Failed {
        id: u64,
        failure: Failure,
    },
    /// How long the server said a new job would wait now for a slot, or the wait a
    /// refusal carried (its load; see [`LOAD_HIGH_WAIT`](super::policy::LOAD_HIGH_WAIT)).
    ServerLoad {
        wait: std::time::Duration,
    },
    /// The round trip of a look at the server's load that it answered: the link's own,
    /// which no bake or queue lengthens (see the manager's `link_scale` module).
    LinkRoundTrip {
        round_trip: std::time::Duration,
    },
}

/// Why a request ended without its final texture.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Failure {
    /// The server (or the generator) refused it or broke off, saying this.
    #[error("{0}")]
    Refused(String),
    /// No answer came within the request's deadline; it was withdrawn.
    #[error("no texture within {0:?}: withdrawn")]
    TimedOut(std::time::Duration),
    /// A prediction the saturated server refused: on arrival, foreseeing this wait;
    /// from its queue, this late past its need.
    #[error("the server is saturated ({0:?} foreseen, or late)")]
    Shed(std::time::Duration),
}
