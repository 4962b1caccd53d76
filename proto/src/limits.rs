//! The sizes every process agrees on for what crosses the wire, in one place.

/// Scenes travel in pieces of at most this many bytes (uploads and fetches alike): far
/// under every message limit below, and a few milliseconds each on a slow link.
pub const SCENE_CHUNK_BYTES: usize = 1 << 20;

/// The largest message a server takes from an upload (one scene chunk, compressed or
/// not): room to spare over [`SCENE_CHUNK_BYTES`] for a peer that chunks differently.
pub const MAX_UPLOAD_MESSAGE_BYTES: usize = 64 << 20;

/// The largest texture message, either way: a 4096² texture with 16-bit depth is 134 MB
/// before compression.
pub const MAX_TEXTURE_MESSAGE_BYTES: usize = 256 << 20;

/// The largest message a server takes from a client asking for or withdrawing textures
/// (a request is about a hundred bytes; a withdrawal of 8,000 ids fits).
pub const MAX_REQUEST_MESSAGE_BYTES: usize = 64 << 10;

/// The longest `client_id`, bytes: it is kept with every waiting request.
pub const MAX_CLIENT_ID_BYTES: usize = 256;

/// The largest scene message a worker takes when it fetches a scene.
pub const MAX_SCENE_FETCH_MESSAGE_BYTES: usize = 1 << 30;

/// The most a request's `serve_within` may be (about 29° of turn about the object): a
/// texture from farther round shows its object worse than any tolerance a client uses
/// would accept, so a larger reach is a client's mistake, refused by name.
pub const MAX_SERVE_WITHIN: f32 = 0.5;
