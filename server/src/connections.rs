//! Accepting connections within bounds: at most so many open at once, each required
//! to start speaking (the HTTP/2 preface, or a TLS hello) within a deadline and closed
//! once it has had no call open for a while, and a listener that backs off instead of
//! spinning when the process runs out of file descriptors.
//!
//! Without these, a thousand idle TCP connections that never sent a byte took every
//! descriptor of a server limited to 1,024: `accept` then failed at once, again and
//! again (a core at 90 %), and every honest client's call timed out. A connection that
//! spoke and then fell silent answers the server's keepalive pings, so it would hold
//! its place for ever: [`CountCalls`] counts each connection's open calls (a streamed
//! answer counts until its last frame), and a connection with none for
//! [`Bounds::idle_within`] is closed. A client that asks for a large texture and does
//! not read it leaves the answer's encoded copy with the server, the rest of it waiting
//! on HTTP/2 flow control: a connection one of whose answers has had a frame waiting to
//! be taken for [`Bounds::stalled_within`] is closed too.
//!
//! ```no_run
//! # async fn serve() -> std::io::Result<()> {
//! use std::time::Duration;
//! use relief_server::connections::{Bounds, CountCalls, accept_within};
//!
//! let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
//! let bounds = Bounds {
//!     max_open: 512,
//!     first_bytes_within: Duration::from_secs(5),
//!     idle_within: Duration::from_secs(60),
//!     stalled_within: Duration::from_secs(30),
//! };
//! let incoming = accept_within(listener, bounds);
//! // … `tonic::transport::Server::builder().layer(CountCalls).…serve_with_incoming(incoming)`
//! # Ok(())
//! # }
//! ```

use std::future::Future;
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio::time::Sleep;
use tokio_stream::wrappers::ReceiverStream;
use tonic::codegen::http;
use tonic::transport::server::{Connected, TcpConnectInfo};

/// Bytes a connection must send before [`Bounds::first_bytes_within`]: the HTTP/2
/// client preface is 24 bytes (a TLS hello is longer).
const OPENING_BYTES: usize = 24;

/// How long the listener waits after `accept` fails (out of descriptors, say) before
/// trying again.
const ACCEPT_BACKOFF: Duration = Duration::from_millis(100);

/// The bounds on connections.
#[derive(Debug, Clone, Copy)]
pub struct Bounds {
    /// Connections open at once; more wait in the kernel's backlog.
    pub max_open: usize,
    /// A connection that has not sent its opening bytes by then is closed.
    pub first_bytes_within: Duration,
    /// A connection with no call open for this long is closed (with
    /// [`CountCalls`] on the server; without it every connection counts as idle).
    pub idle_within: Duration,
    /// A connection one of whose answers has waited this long for its next frame to be
    /// taken (its reader not reading) is closed (with [`CountCalls`]).
    pub stalled_within: Duration,
}

/// The connections `listener` accepts, within `bounds`, as a stream for
/// `serve_with_incoming`. (Accepting runs on a task of its own until the stream is
/// dropped.)
pub fn accept_within(listener: TcpListener, bounds: Bounds) -> ReceiverStream<std::io::Result<Bounded>> {
    let (tx, rx) = mpsc::channel(1);
    let open = Arc::new(Semaphore::new(bounds.max_open));
    tokio::spawn(async move {
        loop {
            let Ok(permit) = open.clone().acquire_owned().await else {
                return;
            };
            match listener.accept().await {
                Ok((stream, _)) => {
                    let _ = stream.set_nodelay(true);
                    let connection = Bounded {
                        stream,
                        _open: permit,
                        opening: Some((0, Box::pin(tokio::time::sleep(bounds.first_bytes_within)))),
                        activity: Arc::new(Activity::new()),
                        idle_within: bounds.idle_within,
                        stalled_within: bounds.stalled_within,
                        // (The first look as soon as either limit could be reached.)
                        idle_check: Box::pin(tokio::time::sleep(
                            bounds.idle_within.min(bounds.stalled_within / 4),
                        )),
                    };
                    if tx.send(Ok(connection)).await.is_err() {
                        return;
                    }
                }
                Err(e) => {
                    tracing::warn!("accepting a connection: {e}");
                    tokio::time::sleep(ACCEPT_BACKOFF).await;
                }
            }
        }
    });
    ReceiverStream::new(rx)
}

/// An accepted connection: it holds its place among the open ones until dropped, and
/// fails its reads once it has been silent past its deadline before its opening bytes,
/// or has had no call open for [`Bounds::idle_within`].
pub struct Bounded {
    stream: TcpStream,
    _open: OwnedSemaphorePermit,
    /// Bytes read so far and the deadline, until the opening bytes are in.
    opening: Option<(usize, Pin<Box<Sleep>>)>,
    activity: Arc<Activity>,
    idle_within: Duration,
    stalled_within: Duration,
    /// When next to see whether the connection has been idle, or stalled, too long.
    idle_check: Pin<Box<Sleep>>,
}

/// A connection's open calls, and since when it has had none: shared by its reads and
/// by [`CountCalls`], which sees its calls.
#[derive(Debug)]
pub struct Activity {
    calls: AtomicUsize,
    /// When the last call ended (or the connection opened), ms after `epoch`.
    idle_since_ms: AtomicU64,
    epoch: Instant,
    /// The open calls whose answer handed a frame over that has not been followed by
    /// a call for the next one, and since when (by call number).
    waiting: std::sync::Mutex<std::collections::HashMap<u64, Instant>>,
    next_call: AtomicU64,
}

impl Activity {
    fn new() -> Activity {
        Activity {
            calls: AtomicUsize::new(0),
            idle_since_ms: AtomicU64::new(0),
            epoch: Instant::now(),
            waiting: Default::default(),
            next_call: AtomicU64::new(0),
        }
    }

    /// How long the answer waiting longest for its next frame to be taken has waited.
    fn stalled_for(&self) -> Duration {
        let waiting = self.waiting.lock().unwrap_or_else(|e| e.into_inner());
        waiting
            .values()
            .map(|since| since.elapsed())
            .max()
            .unwrap_or_default()
    }

    /// Call `call`'s answer handed a frame over (`Some(now)`) or is asked for the next
    /// (`None`).
    fn set_waiting(&self, call: u64, since: Option<Instant>) {
        let mut waiting = self.waiting.lock().unwrap_or_else(|e| e.into_inner());
        match since {
            Some(since) => waiting.insert(call, since),
            None => waiting.remove(&call),
        };
    }

    /// How long the connection has had no call open; `None` while one is.
    fn idle_for(&self) -> Option<Duration> {
        (self.calls.load(Ordering::Acquire) == 0).then(|| {
            let since = Duration::from_millis(self.idle_since_ms.load(Ordering::Acquire));
            self.epoch.elapsed().saturating_sub(since)
        })
    }
}

/// One open call of a connection, from its request to its answer's last frame, and
/// its number among the connection's calls.
struct OpenCall(Arc<Activity>, u64);

impl OpenCall {
    fn new(activity: Arc<Activity>) -> OpenCall {
        activity.calls.fetch_add(1, Ordering::AcqRel);
        let number = activity.next_call.fetch_add(1, Ordering::Relaxed);
        OpenCall(activity, number)
    }
}

impl Drop for OpenCall {
    fn drop(&mut self) {
        self.0.set_waiting(self.1, None);
        let now = self.0.epoch.elapsed().as_millis() as u64;
        self.0.idle_since_ms.store(now, Ordering::Release);
        self.0.calls.fetch_sub(1, Ordering::AcqRel);
    }
}

impl AsyncRead for Bounded {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        let this = &mut *self;
        if let Some((_, deadline)) = &mut this.opening
            && deadline.as_mut().poll(cx).is_ready()
        {
            return Poll::Ready(Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                "the connection sent nothing in time",
            )));
        }
        // (Looked at when the check falls due, then re-armed for when the connection
        // would next be idle too long, or, with calls open, a quarter of the stall
        // limit on.)
        while this.idle_check.as_mut().poll(cx).is_ready() {
            let wait = match this.activity.idle_for() {
                Some(idle) if idle >= this.idle_within => {
                    return Poll::Ready(Err(std::io::Error::new(
                        std::io::ErrorKind::TimedOut,
                        "the connection had no call open in time",
                    )));
                }
                Some(idle) => this.idle_within - idle,
                None if this.activity.stalled_for() >= this.stalled_within => {
                    return Poll::Ready(Err(std::io::Error::new(
                        std::io::ErrorKind::TimedOut,
                        "an answer on the connection was not read in time",
                    )));
                }
                None => this.stalled_within / 4,
            };
            let next = tokio::time::Instant::now() + wait;
            this.idle_check.as_mut().reset(next);
        }
        let before = buf.filled().len();
        let read = Pin::new(&mut this.stream).poll_read(cx, buf);
        if let (Poll::Ready(Ok(())), Some((bytes, _))) = (&read, &mut this.opening) {
            *bytes += buf.filled().len() - before;
            if *bytes >= OPENING_BYTES {
                this.opening = None;
            }
        }
        read
    }
}

impl AsyncWrite for Bounded {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.stream.is_write_vectored()
    }
}

/// What tonic puts in each request's extensions for a [`Bounded`] connection.
#[derive(Debug, Clone)]
pub struct BoundedInfo {
    pub tcp: TcpConnectInfo,
    activity: Arc<Activity>,
}

impl Connected for Bounded {
    type ConnectInfo = BoundedInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        BoundedInfo {
            tcp: self.stream.connect_info(),
            activity: self.activity.clone(),
        }
    }
}

/// The layer that counts each [`Bounded`] connection's open calls (for
/// [`Bounds::idle_within`]): a call is open from its request until its answer's body
/// ends or is dropped — a worker's session or a streamed texture as long as it lasts.
#[derive(Debug, Clone, Copy, Default)]
pub struct CountCalls;

impl<S> tower_layer::Layer<S> for CountCalls {
    type Service = Counted<S>;

    fn layer(&self, inner: S) -> Counted<S> {
        Counted { inner }
    }
}

/// A service whose calls [`CountCalls`] counts.
#[derive(Debug, Clone)]
pub struct Counted<S> {
    inner: S,
}

impl<S, B> tonic::codegen::Service<http::Request<B>> for Counted<S>
where
    S: tonic::codegen::Service<http::Request<B>, Response = http::Response<tonic::body::Body>>,
    S::Future: Send + 'static,
{
    type Response = http::Response<tonic::body::Body>;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<Self::Response, S::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), S::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        let call =
            (request.extensions().get::<BoundedInfo>()).map(|info| OpenCall::new(info.activity.clone()));
        let answer = self.inner.call(request);
        Box::pin(async move {
            let response = answer.await?;
            Ok(match call {
                Some(call) => response.map(|body| {
                    tonic::body::Body::new(CountedBody {
                        body,
                        call,
                        rest: None,
                    })
                }),
                None => response,
            })
        })
    }
}

/// The largest part of an answer handed to HTTP/2 at once. tonic encodes a message
/// into one frame (a large texture: megabytes); handed over whole, it sits in the
/// HTTP/2 stream's send buffer, where nothing sees whether its reader reads. In parts,
/// the stream asks for the next only as its reader makes room, and a part left waiting
/// says the reader stopped.
const ANSWER_PART_BYTES: usize = 64 * 1024;

/// A response body that holds its call open until it ends (or is dropped), handed over
/// in parts of at most [`ANSWER_PART_BYTES`].
struct CountedBody {
    body: tonic::body::Body,
    call: OpenCall,
    /// The rest of a data frame larger than a part.
    rest: Option<tonic::codegen::Bytes>,
}

impl http_body::Body for CountedBody {
    type Data = tonic::codegen::Bytes;
    type Error = tonic::Status;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        // Asked for a frame: whatever was handed over has been taken. One handed over
        // now waits until the next ask — long only when flow control holds it, the
        // reader not reading.
        let this = &mut *self;
        let OpenCall(activity, number) = &this.call;
        activity.set_waiting(*number, None);
        let frame = match this.rest.take() {
            Some(rest) => Poll::Ready(Some(Ok(http_body::Frame::data(rest)))),
            None => Pin::new(&mut this.body).poll_frame(cx),
        };
        let frame = frame.map(|frame| {
            frame.map(|frame| {
                frame.map(|frame| match frame.into_data() {
                    Ok(mut data) => {
                        if data.len() > ANSWER_PART_BYTES {
                            this.rest = Some(data.split_off(ANSWER_PART_BYTES));
                        }
                        http_body::Frame::data(data)
                    }
                    Err(frame) => frame,
                })
            })
        });
        if let Poll::Ready(Some(Ok(_))) = &frame {
            activity.set_waiting(*number, Some(Instant::now()));
        }
        frame
    }

    fn is_end_stream(&self) -> bool {
        self.rest.is_none() && self.body.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        let rest = self.rest.as_ref().map_or(0, |r| r.len() as u64);
        let inner = self.body.size_hint();
        let mut hint = http_body::SizeHint::new();
        hint.set_lower(inner.lower().saturating_add(rest));
        if let Some(upper) = inner.upper() {
            hint.set_upper(upper.saturating_add(rest));
        }
        hint
    }
}
