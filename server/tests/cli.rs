//! The server's command line: help, bad flags, a port that cannot be bound.

use std::process::Command;

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_relief-server"))
        .args(args)
        .env_remove("RELIEF_LISTEN")
        .output()
        .expect("running relief-server");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn help_and_bad_flags() {
    let (code, stdout, _) = run(&["--help"]);
    assert_eq!(code, 0);
    assert!(
        stdout.contains("--listen") && stdout.contains("RELIEF_TOKEN"),
        "{stdout}"
    );
    let (code, _, stderr) = run(&["--listen", "not-an-address"]);
    assert_eq!(code, 2);
    assert!(
        stderr.lines().count() == 1 && stderr.contains("--listen"),
        "{stderr}"
    );
    let (code, _, stderr) = run(&["--lease-ms", "5"]);
    assert_eq!(code, 2, "{stderr}");
}

#[test]
fn a_taken_port_is_a_clear_error() {
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = taken.local_addr().unwrap().to_string();
    let (code, _, stderr) = run(&["--listen", &address]);
    assert_eq!(code, 1);
    assert!(
        stderr.starts_with("error: binding") && stderr.contains(&address),
        "{stderr}"
    );
}
