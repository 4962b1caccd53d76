//! Helpers for Relief's end-to-end tests: find the real binaries, make scratch
//! directories, write small meshes, put a [`relay`] between processes, run them on
//! separate network stacks ([`netns`]).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use relief_core::scratch::PrivateDir;

pub mod netns;
pub mod oracle;
pub mod relay;

/// The directory holding the workspace's binaries: the one above this test executable's
/// `deps/` directory (`target/<profile>/`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let deps = exe.parent().expect("deps directory");
    deps.parent().expect("profile directory").to_path_buf()
}

/// A command for one of the workspace's binaries, e.g. `relief`. Its temp dir
/// (`TMPDIR`) is `target/<profile>/test-tmp`: the scene directories of servers and
/// workers a test kills (rather than stops) stay out of the system's temp dir, and
/// `cargo clean` removes them.
///
/// # Panics
/// When the binary has not been built (run the tests with `cargo test --workspace`,
/// which builds every binary that has integration tests).
pub fn command(name: &str) -> Command {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} is missing: build the workspace first",
        path.display()
    );
    let temp = bin_dir().join("test-tmp");
    std::fs::create_dir_all(&temp).expect("creating the binaries' temp dir");
    let mut command = Command::new(path);
    command.env("TMPDIR", temp);
    command
}

/// Runs `relief` with `args` and returns its output.
pub fn relief(args: &[&str]) -> Output {
    command("relief").args(args).output().expect("running relief")
}

/// A fresh, empty scratch directory under the system's temp dir, removed when dropped
/// (kept when its test fails: [`PrivateDir`]).
pub fn scratch(tag: &str) -> PrivateDir {
    PrivateDir::new(&format!("relief-test-{tag}")).expect("creating a scratch dir")
}

/// The shared real meshes beside the checkout (`../shared/models`).
///
/// # Panics
/// When they are not there: the tests that need them fail rather than pass without
/// checking anything (CI runs with `../shared` beside the clone).
pub fn shared_models() -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/models");
    assert!(
        dir.is_dir(),
        "{} is missing: these tests need the shared meshes beside the checkout",
        dir.display()
    );
    dir
}

/// A child process killed (not just dropped) when the test is done with it.
pub struct Running(pub std::process::Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts `relief-server` on an ephemeral 127.0.0.1 port with `extra` flags; returns
/// the process and its URL (read from the line it prints once bound).
pub fn start_server(extra: &[&str]) -> (Running, String) {
    start_server_at("127.0.0.1:0", extra)
}

/// [`start_server`] listening on `address` (e.g. a port a server before it had).
pub fn start_server_at(address: &str, extra: &[&str]) -> (Running, String) {
    let mut server = command("relief-server");
    server.args(["--listen", address]).args(extra);
    spawn_server(server)
}

/// Starts the server `server` describes (its `--listen` and flags set); returns the
/// process and its URL.
pub fn spawn_server(mut server: Command) -> (Running, String) {
    use std::io::{BufRead, BufReader};
    let mut child = server
        .stdout(std::process::Stdio::piped())
        .spawn()
        .expect("starting relief-server");
    let stdout = child.stdout.take().expect("server stdout");
    let mut line = String::new();
    BufReader::new(stdout)
        .read_line(&mut line)
        .expect("reading the server's address");
    let url = line
        .trim()
        .strip_prefix("relief-server listening on ")
        .unwrap_or_else(|| panic!("unexpected first line from relief-server: {line:?}"))
        .to_string();
    (Running(child), url)
}

/// Sends SIGTERM to `child`: what a service manager sends to stop it in good order.
pub fn send_sigterm(child: &std::process::Child) {
    let pid = child.id().to_string();
    let sent = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("running kill");
    assert!(sent.success(), "kill -TERM {pid}");
}

/// Waits, at most `within`, for `child` to exit.
///
/// # Panics
/// When it is still running after `within`.
pub fn wait_exit(child: &mut std::process::Child, within: std::time::Duration) -> std::process::ExitStatus {
    let start = std::time::Instant::now();
    loop {
        if let Some(status) = child.try_wait().expect("waiting for the child") {
            return status;
        }
        assert!(
            start.elapsed() < within,
            "process {} still running after {within:?}",
            child.id()
        );
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// A `relief-worker` command dialling `url` (heartbeats every 100 ms), for more flags
/// or environment before it starts.
pub fn worker_command(url: &str) -> Command {
    let mut worker = command("relief-worker");
    worker.args(["--server", url, "--heartbeat-ms", "100"]);
    worker
}

/// Starts a `relief-worker` dialling `url`.
pub fn start_worker(url: &str, extra: &[&str]) -> Running {
    let child = worker_command(url)
        .args(extra)
        .spawn()
        .expect("starting relief-worker");
    Running(child)
}

/// A client of the server at `url` (sending `token`, as `client_id`) that has uploaded
/// the default scene, and the scene's hash.
pub async fn upload_default(
    url: &str,
    token: Option<&str>,
    client_id: &str,
) -> (relief_client::remote::Remote, String) {
    let mut remote = relief_client::remote::Remote::connect(url, token, client_id)
        .await
        .expect("connect");
    let bundle = relief_proto::bundle::bundle_for("default").expect("the default scene");
    let hash = remote.put_scene(&bundle).await.expect("upload").to_string();
    (remote, hash)
}

/// Waits (at most 30 s, polling) until `check` holds on the server's counters, and
/// returns them.
pub async fn wait_for(
    remote: &mut relief_client::remote::Remote,
    what: &str,
    check: impl Fn(&relief_proto::pb::StatsReply) -> bool,
) -> relief_proto::pb::StatsReply {
    let start = std::time::Instant::now();
    loop {
        let stats = remote.stats().await.expect("stats");
        if check(&stats) {
            return stats;
        }
        assert!(
            start.elapsed() < std::time::Duration::from_secs(30),
            "timed out waiting for {what}: {stats:?}"
        );
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
}

/// The Python of a virtual environment under `target/` holding the packages of
/// `tests/foreign/requirements.txt` (stock gRPC, Prometheus and Kubernetes tools the
/// tests check Relief against), created and filled on first use: PyPI must be
/// reachable then.
pub fn foreign_python() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let venv = bin_dir().join("foreign-venv");
    let python = venv.join("bin/python");
    let requirements = root.join("foreign/requirements.txt");
    let stamp = venv.join("installed.txt");
    let wanted = std::fs::read_to_string(&requirements).expect("requirements.txt");
    if std::fs::read_to_string(&stamp).ok().as_deref() != Some(wanted.as_str()) {
        let ok = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .expect("python3 -m venv");
        assert!(ok.success(), "creating the venv failed");
        let ok = Command::new(&python)
            .args([
                "-m",
                "pip",
                "install",
                "--quiet",
                "--disable-pip-version-check",
                "-r",
            ])
            .arg(&requirements)
            .status()
            .expect("pip install");
        assert!(ok.success(), "installing {} failed", requirements.display());
        std::fs::write(&stamp, wanted).expect("writing the venv stamp");
    }
    python
}
