//! The one shutdown signal of the long-running binaries (server and worker).

use tokio::sync::watch;

/// Watches for [`signal`] from a task of its own: the receiver's value turns true once
/// it arrives. (Call within a Tokio runtime.)
pub fn watch() -> watch::Receiver<bool> {
    let (stop_tx, stop) = watch::channel(false);
    tokio::spawn(async move {
        signal().await;
        let _ = stop_tx.send(true);
    });
    stop
}

/// Resolves on SIGINT (Ctrl-C) or, on Unix, SIGTERM — what service managers and
/// container runtimes send to stop a process in good order.
pub async fn signal() {
    #[cfg(unix)]
    {
        use tokio::signal::unix::{SignalKind, signal};
        match signal(SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            }
            Err(_) => {
                let _ = tokio::signal::ctrl_c().await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = tokio::signal::ctrl_c().await;
    }
}
