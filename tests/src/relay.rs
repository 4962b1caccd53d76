//! A TCP relay in user space between a test's processes on 127.0.0.1: what a network
//! does to a link, without `netem` (this kernel has none) — a delay each way, packet
//! loss, and a partition that can be cut and healed.
//!
//! Loss is modelled as TCP lives it, since the relay sees streams, not packets: each
//! [`SEGMENT_BYTES`] of a stream is lost with the link's probability, and a loss holds
//! back what it was read with and all that follows on its connection — by a round trip
//! when enough follows it in the same read for the receiver's duplicate
//! acknowledgements to ask for it again (fast retransmit), else by a retransmission
//! timeout (twice the round trip, [`MIN_RTO`] at least). So a loss near the end of a
//! read pays the timeout even when the next read follows at once: harsher than TCP
//! there.
//!
//! A connection opens a round trip after it is asked for (the handshake), and a lost
//! handshake costs the kernel's first SYN retry ([`SYN_RETRY`]) more.
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

use relief_core::generators::SplitMix64;

/// How often a relay in a cut looks whether the link is back.
const CUT_POLL: Duration = Duration::from_millis(10);

/// The bytes of one TCP segment on an Ethernet path (1500-byte MTU less the headers).
pub const SEGMENT_BYTES: usize = 1448;

/// Linux's least retransmission timeout: what a lost segment at the end of a burst
/// (no duplicate acknowledgements to trigger fast retransmit) waits at least.
pub const MIN_RTO: Duration = Duration::from_millis(200);

/// Segments that must follow a lost one for three duplicate acknowledgements to ask
/// for it again after one round trip.
const FAST_RETRANSMIT_AFTER: usize = 3;

/// Linux's first SYN retransmission: what a lost handshake costs a new connection.
pub const SYN_RETRY: Duration = Duration::from_secs(1);

/// What a relayed link does: a delay each way, and the probability each segment (or
/// handshake) is lost.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Link {
    pub delay: Duration,
    pub loss: f64,
}

/// A seed for each connection's losses: runs differ only by what the processes do.
static CONNECTIONS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

/// Whether this segment (or handshake) is lost: `rng`'s next draw under `loss`.
fn lost(rng: &mut SplitMix64, loss: f64) -> bool {
    loss > 0.0 && f64::from(rng.range(0.0, 1.0)) < loss
}

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
        Relay::start_link(listen, target, Link { delay, loss: 0.0 }).await
    }

    /// A relay listening on `listen` (`host:port`; port 0 picks one) to `target` over
    /// `link`.
    pub async fn start_link(listen: &str, target: &str, link: Link) -> Relay {
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
                        let seed = CONNECTIONS.fetch_add(1, Ordering::Relaxed);
                        let mut rng = SplitMix64::new(seed);
                        // (The handshake: a SYN each way.)
                        let mut opening = link.delay * 2;
                        if lost(&mut rng, link.loss) || lost(&mut rng, link.loss) {
                            opening += SYN_RETRY;
                        }
                        tokio::time::sleep(opening).await;
                        wait_healed(&cut).await;
                        let Ok(outbound) = TcpStream::connect(&target).await else {
                            return;
                        };
                        let _ = (inbound.set_nodelay(true), outbound.set_nodelay(true));
                        let (in_read, in_write) = inbound.into_split();
                        let (out_read, out_write) = outbound.into_split();
                        let back = SplitMix64::new(rng.next_u64());
                        tokio::spawn(pass(in_read, out_write, cut.clone(), link, rng));
                        tokio::spawn(pass(out_read, in_write, cut, link, back));
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

/// Copies `from` to `to`, each chunk `link.delay` after it was read (chunks in flight
/// together, as on a line with that latency), later when it or one before it lost a
/// segment (see the module's notes), and none while the link is cut; closes `to` when
/// `from` ends.
async fn pass(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    cut: Arc<AtomicBool>,
    link: Link,
    mut rng: SplitMix64,
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
    let round_trip = link.delay * 2;
    let mut buffer = vec![0u8; 64 << 10];
    // Nothing on this connection arrives before what a loss held back.
    let mut held_until = tokio::time::Instant::now();
    loop {
        let n = match from.read(&mut buffer).await {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        let arrival = tokio::time::Instant::now() + link.delay;
        let mut due = arrival.max(held_until);
        let segments = n.div_ceil(SEGMENT_BYTES);
        if let Some(k) = (0..segments).find(|_| lost(&mut rng, link.loss)) {
            // (The timeout is the smoothed round trip and four times its variation:
            // about two round trips on a steady link.)
            let recovery = if segments - k > FAST_RETRANSMIT_AFTER {
                round_trip
            } else {
                MIN_RTO.max(round_trip * 2)
            };
            // (Losses within one recovery are resent together, as with selective
            // acknowledgements: they do not add up.)
            due = due.max(arrival + recovery);
        }
        held_until = due;
        if line.send((due, buffer[..n].to_vec())).is_err() {
            break;
        }
    }
    drop(line);
    let _ = writer.await;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sends `bytes` through a relay over `link` to an echo of the first byte, and
    /// times the connection and the answer.
    async fn timed(link: Link, bytes: usize) -> (Duration, Duration) {
        let echo = TcpListener::bind("127.0.0.1:0").await.unwrap();
        let target = echo.local_addr().unwrap().to_string();
        tokio::spawn(async move {
            let (mut s, _) = echo.accept().await.unwrap();
            let mut got = vec![0u8; bytes];
            s.read_exact(&mut got).await.unwrap();
            s.write_all(&got[..1]).await.unwrap();
        });
        let relay = Relay::start_link("127.0.0.1:0", &target, link).await;
        let start = tokio::time::Instant::now();
        let mut s = TcpStream::connect(relay.address).await.unwrap();
        s.write_all(&vec![7u8; bytes]).await.unwrap();
        let mut answer = [0u8; 1];
        s.read_exact(&mut answer).await.unwrap();
        let total = start.elapsed();
        (total, total.saturating_sub(link.delay * 4))
    }

    /// A loss costs what TCP pays for it: a handshake the SYN retry, a segment at a
    /// burst's end the retransmission timeout, one with enough behind it a round trip.
    #[tokio::test]
    async fn losses_cost_what_tcp_pays_for_them() {
        let delay = Duration::from_millis(20);
        let clean = Link { delay, loss: 0.0 };
        let lossy = Link { delay, loss: 1.0 };
        // The handshake's round trip, then there and back: two round trips.
        let (small, _) = timed(clean, 100).await;
        assert!(
            small >= delay * 4 && small < delay * 4 + Duration::from_millis(150),
            "{small:?}"
        );
        // Everything lost: the SYN retry, then each way a short message's tail loss.
        let (_, over) = timed(lossy, 100).await;
        let tail = MIN_RTO.max(delay * 4);
        let least = SYN_RETRY + tail * 2;
        assert!(
            over >= least && over < least + Duration::from_millis(300),
            "{over:?}"
        );
    }
}
