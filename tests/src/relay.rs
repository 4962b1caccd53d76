//! A TCP relay in user space between a test's processes on 127.0.0.1: what a network
//! does to a link, without `netem` (this kernel has none) — a delay each way, and a
//! partition that can be cut and healed.
//!
//! A cut stops the bytes in both directions without closing anything, as a partition
//! does: what was sent waits in the relay (and, behind it, in the senders' buffers),
//! and arrives once the link is healed — unless a peer gave up on the connection
//! meanwhile. Connections opened during a cut are accepted but not passed on until it
//! heals.
//!
//! ```no_run
//! # async fn example() {
//! let relay = relief_tests::relay::Relay::start("127.0.0.1:7411", std::time::Duration::ZERO).await;
//! let url = relay.url(); // dial this instead of the server
//! relay.cut();
//! relay.heal();
//! # }
//! ```

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};

/// How often a relay in a cut looks whether the link is back.
const CUT_POLL: Duration = Duration::from_millis(10);

/// A relay listening on an ephemeral 127.0.0.1 port, passing each connection on to
/// its target; it stops when dropped (its connections end with the test's runtime).
pub struct Relay {
    address: std::net::SocketAddr,
    cut: Arc<AtomicBool>,
    accepting: tokio::task::JoinHandle<()>,
}

impl Relay {
    /// A relay on 127.0.0.1 to `target` (`host:port`) adding `delay` to each direction.
    pub async fn start(target: &str, delay: Duration) -> Relay {
        Relay::start_on("127.0.0.1:0", target, delay).await
    }

    /// [`Relay::start`] listening on `listen` (`host:port`; port 0 picks one).
    pub async fn start_on(listen: &str, target: &str, delay: Duration) -> Relay {
        let listener = TcpListener::bind(listen).await.expect("binding the relay");
        let address = listener.local_addr().expect("the relay's address");
        let cut = Arc::new(AtomicBool::new(false));
        let target = target.to_string();
        let accepting = tokio::spawn({
            let cut = cut.clone();
            async move {
                while let Ok((inbound, _)) = listener.accept().await {
                    let (cut, target) = (cut.clone(), target.clone());
                    tokio::spawn(async move {
                        wait_healed(&cut).await;
                        let Ok(outbound) = TcpStream::connect(&target).await else {
                            return;
                        };
                        let _ = (inbound.set_nodelay(true), outbound.set_nodelay(true));
                        let (in_read, in_write) = inbound.into_split();
                        let (out_read, out_write) = outbound.into_split();
                        tokio::spawn(pass(in_read, out_write, cut.clone(), delay));
                        tokio::spawn(pass(out_read, in_write, cut, delay));
                    });
                }
            }
        });
        Relay {
            address,
            cut,
            accepting,
        }
    }

    /// `http://` and the relay's address: what to dial instead of the target.
    pub fn url(&self) -> String {
        format!("http://{}", self.address)
    }

    /// Cuts the link: no byte passes either way until [`Relay::heal`].
    pub fn cut(&self) {
        self.cut.store(true, Ordering::SeqCst);
    }

    /// Heals the link: what waited passes on.
    pub fn heal(&self) {
        self.cut.store(false, Ordering::SeqCst);
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.accepting.abort();
    }
}

async fn wait_healed(cut: &AtomicBool) {
    while cut.load(Ordering::SeqCst) {
        tokio::time::sleep(CUT_POLL).await;
    }
}

/// Copies `from` to `to`, each chunk `delay` after it was read (chunks in flight
/// together, as on a line with that latency) and none while the link is cut; closes
/// `to` when `from` ends.
async fn pass(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    cut: Arc<AtomicBool>,
    delay: Duration,
) {
    let (line, mut arriving) = tokio::sync::mpsc::unbounded_channel::<(tokio::time::Instant, Vec<u8>)>();
    let writer = tokio::spawn(async move {
        while let Some((due, bytes)) = arriving.recv().await {
            tokio::time::sleep_until(due).await;
            wait_healed(&cut).await;
            if to.write_all(&bytes).await.is_err() {
                return;
            }
        }
        let _ = to.shutdown().await;
    });
    let mut buffer = vec![0u8; 64 << 10];
    loop {
        let n = match from.read(&mut buffer).await {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        let due = tokio::time::Instant::now() + delay;
        if line.send((due, buffer[..n].to_vec())).is_err() {
            break;
        }
    }
    drop(line);
    let _ = writer.await;
}
