//! The deployment recipes stay in step with the code: the Kubernetes manifests
//! validate against the Kubernetes schemas (offline, strict), every flag and
//! environment variable they give a container is one its binary knows, and the
//! container image builds with the toolchain the workspace names, as a user without
//! privileges.

use std::path::Path;
use std::process::Command;

use relief_tests::{command, foreign_python};

fn repo() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

#[test]
fn the_kubernetes_manifests_validate_and_name_only_real_flags() {
    let manifests: Vec<_> = std::fs::read_dir(repo().join("deploy/kubernetes"))
        .expect("deploy/kubernetes")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "yaml"))
        .collect();
    assert!(manifests.len() >= 2, "{manifests:?}");
    let out = Command::new(foreign_python())
        .arg(repo().join("tests/foreign/manifests.py"))
        .args(&manifests)
        .output()
        .expect("running the manifest validator");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let containers: Vec<serde_json::Value> = serde_json::from_str(stdout.trim()).expect("one JSON list");
    let mut binaries = std::collections::BTreeSet::new();
    for container in &containers {
        let binary = container["command"][0].as_str().expect("a command");
        binaries.insert(binary.to_string());
        let help = command(binary).arg("--help").output().expect("--help");
        let help = String::from_utf8_lossy(&help.stdout);
        let args = container["args"]
            .as_array()
            .unwrap()
            .iter()
            .map(|a| a.as_str().unwrap());
        for flag in args.filter(|a| a.starts_with("--")) {
            let name = flag.split('=').next().unwrap();
            assert!(
                help.contains(&format!("{name} ")),
                "{binary} has no {name} ({container})"
            );
        }
        for variable in container["env"].as_array().unwrap() {
            let variable = variable.as_str().unwrap();
            assert!(
                help.contains(&format!("env: {variable}")),
                "{binary} reads no {variable}"
            );
        }
    }
    let expected: std::collections::BTreeSet<String> =
        ["relief-server", "relief-worker"].map(String::from).into();
    assert_eq!(binaries, expected);
}

#[test]
fn the_image_builds_with_the_workspace_toolchain_as_an_unprivileged_user() {
    let dockerfile = std::fs::read_to_string(repo().join("deploy/Dockerfile")).unwrap();
    let manifest = std::fs::read_to_string(repo().join("Cargo.toml")).unwrap();
    let rust_version = manifest
        .lines()
        .find_map(|l| l.strip_prefix("rust-version = \""))
        .and_then(|v| v.strip_suffix('"'))
        .expect("the workspace's rust-version");
    assert!(
        dockerfile.contains(&format!("FROM rust:{rust_version}-")),
        "the build stage's toolchain is not the workspace's {rust_version}"
    );
    let user = dockerfile
        .lines()
        .rev()
        .find_map(|l| l.strip_prefix("USER "))
        .expect("a USER line");
    assert!(
        !user.starts_with("0") && !user.starts_with("root"),
        "runs as {user}"
    );
    assert!(
        dockerfile.contains("--locked"),
        "the image builds from Cargo.lock"
    );
}
