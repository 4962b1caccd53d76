//! The client's side of the protocol: upload scenes, ask for relief textures, withdraw
//! predictions, read the server's counters.

use tonic::codec::CompressionEncoding;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::Channel;
use tonic::{Status, Streaming};

use relief_core::hash::ContentHash;
use relief_proto::auth::BearerToken;
use relief_proto::bundle::Bundle;
use relief_proto::convert::hash_from_pb;
use relief_proto::limits::{MAX_TEXTURE_MESSAGE_BYTES, SCENE_CHUNK_BYTES};
use relief_proto::pb;

type Impostors = pb::impostors_client::ImpostorsClient<InterceptedService<Channel, BearerToken>>;
type Scenes = pb::scenes_client::ScenesClient<InterceptedService<Channel, BearerToken>>;

/// A connection to a Relief server.
#[derive(Clone)]
pub struct Remote {
    scenes: Scenes,
    impostors: Impostors,
    /// This client's id in requests and withdrawals.
    pub client_id: String,
}

/// Why a connection or a wait failed; each names the server or the problem.
#[derive(Debug, thiserror::Error)]
pub enum RemoteError {
    #[error(transparent)]
    Endpoint(#[from] relief_proto::connect::EndpointError),
    #[error("connecting to {url}: {}", relief_proto::connect::explain(error))]
    Connect {
        url: String,
        error: tonic::transport::Error,
    },
    #[error(transparent)]
    Token(#[from] relief_proto::auth::TokenError),
    /// A call the server answered with an error.
    #[error("{}", .0.message())]
    Call(#[from] Status),
    #[error("{registered} of {wanted} workers registered within {limit:?}")]
    TooFewWorkers {
        registered: u32,
        wanted: u32,
        limit: std::time::Duration,
    },
}

/// How often [`Remote::wait_for_workers`] asks the server.
const WORKER_POLL: std::time::Duration = std::time::Duration::from_millis(20);

impl Remote {
    /// Connects to `url` (e.g. `http://127.0.0.1:7411`); errors name the problem.
    pub async fn connect(url: &str, token: Option<&str>, client_id: &str) -> Result<Remote, RemoteError> {
        Self::connect_with(url, token, None, client_id).await
    }

    /// As [`Remote::connect`], trusting the certificates in the PEM file `ca` too (for
    /// an `https://` server with a self-signed certificate).
    pub async fn connect_with(
        url: &str,
        token: Option<&str>,
        ca: Option<&std::path::Path>,
        client_id: &str,
    ) -> Result<Remote, RemoteError> {
        let endpoint = relief_proto::connect::endpoint(url, ca)?;
        let channel = endpoint.connect().await.map_err(|error| RemoteError::Connect {
            url: url.to_string(),
            error,
        })?;
        let auth = BearerToken::new(token)?;
        Ok(Remote {
            scenes: pb::scenes_client::ScenesClient::with_interceptor(channel.clone(), auth.clone())
                .send_compressed(CompressionEncoding::Zstd)
                .accept_compressed(CompressionEncoding::Zstd),
            // Requests to Impostors are a few bytes, and textures come with their planes
            // compressed (see `relief_proto::planes`): both plain on the wire.
            impostors: pb::impostors_client::ImpostorsClient::with_interceptor(channel, auth)
                .max_decoding_message_size(MAX_TEXTURE_MESSAGE_BYTES),
            client_id: client_id.to_string(),
        })
    }

    /// Uploads a scene; returns the hash the server stored it under.
    pub async fn put_scene(&mut self, bundle: &Bundle) -> Result<ContentHash, Status> {
        let chunks: Vec<pb::SceneChunk> = bundle
            .encoded
            .chunks(SCENE_CHUNK_BYTES)
            .map(|c| pb::SceneChunk { data: c.to_vec() })
            .collect();
        let reply = self
            .scenes
            .put_scene(tokio_stream::iter(chunks))
            .await?
            .into_inner();
        hash_from_pb("hash", &reply.hash)
    }

    /// Asks for a texture; the stream yields the preview (if asked) and the final one.
    pub async fn request(
        &mut self,
        request: pb::ImpostorRequest,
    ) -> Result<Streaming<pb::ImpostorResult>, Status> {
        Ok(self.impostors.request(request).await?.into_inner())
    }

    /// Withdraws this client's requests; returns how many were still open.
    pub async fn withdraw(&mut self, request_ids: &[u64]) -> Result<u32, Status> {
        let reply = self
            .impostors
            .withdraw(pb::WithdrawRequest {
                client_id: self.client_id.clone(),
                request_ids: request_ids.to_vec(),
            })
            .await?;
        Ok(reply.into_inner().withdrawn)
    }

    /// Waits until at least `count` workers are registered, polling the counters;
    /// an error after `limit`.
    pub async fn wait_for_workers(
        &mut self,
        count: u32,
        limit: std::time::Duration,
    ) -> Result<(), RemoteError> {
        let start = std::time::Instant::now();
        loop {
            let workers = self.stats().await?.workers;
            if workers >= count {
                return Ok(());
            }
            if start.elapsed() > limit {
                return Err(RemoteError::TooFewWorkers {
                    registered: workers,
                    wanted: count,
                    limit,
                });
            }
            tokio::time::sleep(WORKER_POLL).await;
        }
    }

    /// The server's counters.
    pub async fn stats(&mut self) -> Result<pb::StatsReply, Status> {
        Ok(self.impostors.stats(pb::StatsRequest {}).await?.into_inner())
    }
}
