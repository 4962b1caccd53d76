//! The worker's command line: help and bad flags.

use std::process::Command;

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_relief-worker"))
        .args(args)
        .env_remove("RELIEF_SERVER")
        .output()
        .expect("running relief-worker");
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
    assert!(stdout.contains("--server"), "{stdout}");
    let (code, _, stderr) = run(&[]);
    assert_eq!(code, 2, "--server is required: {stderr}");
    let (code, _, stderr) = run(&["--server", "::nonsense::"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("--server") && stderr.lines().count() == 1,
        "{stderr}"
    );
    let (code, _, _) = run(&["--server", "http://127.0.0.1:1", "--slots", "0"]);
    assert_eq!(code, 2);
}
