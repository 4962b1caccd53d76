//! Accepting connections within bounds: at most so many open at once, each required
//! to start speaking (the HTTP/2 preface, or a TLS hello) within a deadline, and a
//! listener that backs off instead of spinning when the process runs out of file
//! descriptors.
//!
//! Without these, a thousand idle TCP connections that never sent a byte took every
//! descriptor of a server limited to 1,024: `accept` then failed at once, again and
//! again (a core at 90 %), and every honest client's call timed out.
//!
//! ```no_run
//! # async fn serve() -> std::io::Result<()> {
//! use std::time::Duration;
//! use relief_server::connections::{Bounds, accept_within};
//!
//! let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
//! let incoming = accept_within(listener, Bounds { max_open: 512, first_bytes_within: Duration::from_secs(5) });
//! // … `tonic::transport::Server::builder().…serve_with_incoming(incoming)`
//! # Ok(())
//! # }
//! ```

use std::pin::Pin;
use std::sync::Arc;
use std::task::{Context, Poll};
use std::time::Duration;

use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{OwnedSemaphorePermit, Semaphore, mpsc};
use tokio::time::Sleep;
use tokio_stream::wrappers::ReceiverStream;
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
/// fails its reads once it has been silent past its deadline before its opening bytes.
pub struct Bounded {
    stream: TcpStream,
    _open: OwnedSemaphorePermit,
    /// Bytes read so far and the deadline, until the opening bytes are in.
    opening: Option<(usize, Pin<Box<Sleep>>)>,
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

impl Connected for Bounded {
    type ConnectInfo = TcpConnectInfo;

    fn connect_info(&self) -> Self::ConnectInfo {
        self.stream.connect_info()
    }
}
