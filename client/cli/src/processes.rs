//! Child processes of the commands that run the whole system on 127.0.0.1.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use anyhow::{Context, Result, anyhow, bail};

use relief_client::remote::Remote;
use relief_core::hash::ContentHash;
use relief_proto::bundle::Bundle;

/// Child processes, killed when dropped.
struct Children(Vec<Child>);

impl Drop for Children {
    fn drop(&mut self) {
        // Workers before the server they talk to.
        for c in self.0.iter_mut().rev() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

/// A binary installed next to this one.
pub fn sibling(name: &str) -> Result<PathBuf> {
    let exe = std::env::current_exe().context("locating the relief binary")?;
    let path = exe.with_file_name(name);
    if !path.is_file() {
        bail!(
            "{} not found next to {} (build the workspace: cargo build --release)",
            name,
            exe.display()
        );
    }
    Ok(path)
}

/// A server and its workers started on 127.0.0.1 for one run, stopped when dropped.
pub struct LocalService {
    /// The server's URL.
    pub url: String,
    /// (Killed on drop: workers first.)
    _children: Children,
}

impl LocalService {
    /// Starts a server on an ephemeral port and `workers` workers dialling it, their
    /// scenes unpacked under `dir` (`server-scenes/`, `worker-K-scenes/`).
    pub fn start(dir: &Path, workers: u32) -> Result<LocalService> {
        let mut children = Children(Vec::new());
        let url = start_server(&mut children, &dir.join("server-scenes"))?;
        start_workers(&mut children, &url, workers, dir)?;
        Ok(LocalService {
            url,
            _children: children,
        })
    }
}

/// Starts a server on an ephemeral 127.0.0.1 port; returns it and its URL.
fn start_server(children: &mut Children, dir: &Path) -> Result<String> {
    let mut child = Command::new(sibling("relief-server")?)
        // (The standalone server's own lease and the workers' own heartbeat: the
        // demo measures what a deployment gets.)
        .args(["--listen", "127.0.0.1:0"])
        .arg("--scene-dir")
        .arg(dir)
        .stdout(Stdio::piped())
        .spawn()
        .context("starting relief-server")?;
    let stdout = child.stdout.take().context("server stdout")?;
    children.0.push(child);
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .context("reading the server's address")?;
    let url = line
        .trim()
        .strip_prefix("relief-server listening on ")
        .ok_or_else(|| anyhow!("relief-server did not start: {line:?}"))?;
    Ok(url.to_string())
}

/// Starts `count` workers dialling `url`, unpacking scenes under `dir`.
fn start_workers(children: &mut Children, url: &str, count: u32, dir: &Path) -> Result<()> {
    let worker = sibling("relief-worker")?;
    for k in 0..count {
        let child = Command::new(&worker)
            .args(["--server", url, "--name", &format!("local-{k}")])
            .arg("--scene-dir")
            .arg(dir.join(format!("worker-{k}-scenes")))
            .spawn()
            .context("starting relief-worker")?;
        children.0.push(child);
    }
    Ok(())
}

/// How long workers just started may take to register.
const WORKERS_REGISTER_WITHIN: std::time::Duration = std::time::Duration::from_secs(20);

/// Connects to the server at `url` as `client_id` (trusting `ca` besides the system's
/// roots), uploads `bundle`, and — given a count — waits (at most 20 s) until that many
/// workers have registered. Returns the connection and the scene's hash.
pub async fn connect_and_upload(
    url: &str,
    token: Option<&str>,
    ca: Option<&Path>,
    client_id: &str,
    bundle: &Bundle,
    workers: Option<u32>,
) -> Result<(Remote, ContentHash)> {
    let mut remote = Remote::connect_with(url, token, ca, client_id).await?;
    let hash = remote
        .put_scene(bundle)
        .await
        .map_err(|e| anyhow!("uploading the scene: {}", e.message()))?;
    if let Some(count) = workers {
        remote.wait_for_workers(count, WORKERS_REGISTER_WITHIN).await?;
    }
    Ok((remote, hash))
}
