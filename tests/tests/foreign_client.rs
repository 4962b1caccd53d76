//! gRPC clients that are not ours: Python stubs generated from `proto/` by
//! grpc_tools' protoc ask a real server for a relief texture, and Python's stock
//! reflection client lists its services.
//!
//! The Python packages come from `tests/foreign/requirements.txt`, installed into a
//! virtual environment under `target/` on first use (PyPI must be reachable).

use std::path::{Path, PathBuf};
use std::process::Command;

use relief_tests::{scratch, start_server, start_worker};

/// The venv's python, created and filled from requirements.txt when missing.
fn python() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let venv = relief_tests::bin_dir().join("foreign-venv");
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

#[test]
fn a_python_client_generated_from_the_proto_gets_a_texture() {
    let python = python();
    let (_server, url) = start_server(&[]);
    let _worker = start_worker(&url, &[]);
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let (_, hash) = runtime.block_on(relief_tests::upload_default(&url, None, "setup"));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(&python)
        .arg(root.join("foreign/client.py"))
        .arg(root.join("../proto"))
        .arg(scratch("python-stubs"))
        .arg(&url)
        .arg(&hash)
        .output()
        .expect("running the Python client");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let reply: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON line");
    assert_eq!(reply["width"], 64);
    assert_eq!(reply["height"], 64);
    assert_eq!(reply["albedo_bytes"], 64 * 64 * 3);
    assert_eq!(reply["depth_bytes"], 64 * 64);
    let covered = reply["covered"].as_u64().unwrap();
    assert!(covered > 64 * 64 / 4 && covered < 64 * 64, "{reply}");
}

/// Python's `grpcio-reflection`, which asks `grpc.reflection.v1alpha` only, lists the
/// server's services (a server serving reflection `v1` alone answered it UNIMPLEMENTED).
#[test]
fn python_reflection_lists_the_services() {
    let python = python();
    let (_server, url) = start_server(&[]);
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Command::new(&python)
        .arg(root.join("foreign/reflection.py"))
        .arg(url.strip_prefix("http://").unwrap())
        .output()
        .expect("running the Python reflection client");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for service in [
        "relief.v1.Impostors",
        "relief.v1.Scenes",
        "relief.v1.Workers",
        "grpc.health.v1.Health",
    ] {
        assert!(stdout.lines().any(|l| l == service), "{service} not in {stdout}");
    }
}
