//! Bad input to the `relief` command line: one line naming the problem, non-zero exit,
//! never a panic.

use std::path::PathBuf;
use std::process::Command;

fn relief(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_relief"))
        .args(args)
        .output()
        .expect("running relief");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("relief-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Asserts a failed run whose stderr is one `error:` line containing every `needle`.
fn assert_one_line_error(args: &[&str], needles: &[&str]) {
    let (code, _, stderr) = relief(args);
    assert_ne!(code, 0, "{args:?} succeeded");
    assert!(!stderr.contains("panicked"), "{args:?} panicked: {stderr}");
    let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "{args:?}: expected one line, got {stderr:?}");
    assert!(lines[0].starts_with("error:"), "{args:?}: {stderr}");
    for needle in needles {
        assert!(
            lines[0].contains(needle),
            "{args:?}: `{needle}` missing from {stderr:?}"
        );
    }
}

fn bake_args<'a>(scene: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["bake", "--scene", scene, "--out", "/tmp/relief-cli-unused"];
    args.extend_from_slice(extra);
    args
}

#[test]
fn bad_files() {
    let dir = scratch("files");
    let missing = dir.join("missing.obj");
    let missing = missing.to_str().unwrap();
    assert_one_line_error(&bake_args(missing, &["--eye", "0,0,5"]), &["missing.obj"]);

    let broken = dir.join("broken.obj");
    std::fs::write(&broken, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    assert_one_line_error(
        &bake_args(broken.to_str().unwrap(), &["--eye", "0,0,5"]),
        &["broken.obj"],
    );

    let nan = dir.join("nan.obj");
    std::fs::write(&nan, "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    assert_one_line_error(
        &bake_args(nan.to_str().unwrap(), &["--eye", "0,0,5"]),
        &["nan.obj", "vertex 2"],
    );

    let scene = dir.join("bad.toml");
    std::fs::write(&scene, "[[objects]]\nname = \"a\"\nmesh = 3\n").unwrap();
    assert_one_line_error(
        &bake_args(scene.to_str().unwrap(), &["--eye", "0,0,5"]),
        &["bad.toml", "mesh"],
    );

    assert_one_line_error(
        &bake_args("no-such-scene", &["--eye", "0,0,5"]),
        &["no-such-scene", "default"],
    );
}

#[test]
fn bad_objects_and_eyes() {
    assert_one_line_error(
        &bake_args("default", &["--object", "teapot", "--eye", "0,0,5"]),
        &["teapot", "sphere"],
    );
    assert_one_line_error(&bake_args("default", &["--eye", "0,0,5"]), &["--object"]);
    // The sphere is centred at (-3, 1, 0) with radius 1.
    assert_one_line_error(
        &bake_args("default", &["--object", "sphere", "--eye", "-3,1.2,0.1"]),
        &["sphere", "inside", "geometry"],
    );
    assert_one_line_error(
        &bake_args("default", &["--object", "sphere", "--eye", "NaN,0,5"]),
        &["x component"],
    );
    assert_one_line_error(
        &bake_args("default", &["--object", "sphere", "--eye", "0,inf,5"]),
        &["finite"],
    );
    assert_one_line_error(
        &bake_args("default", &["--object", "sphere", "--eye", "0,5"]),
        &["X,Y,Z"],
    );
}

#[test]
fn bad_sizes() {
    for size in ["0", "4097", "-3", "big"] {
        assert_one_line_error(
            &bake_args(
                "default",
                &["--object", "sphere", "--eye", "0,0,5", "--size", size],
            ),
            &["--size"],
        );
    }
    assert_one_line_error(
        &bake_args(
            "default",
            &["--object", "sphere", "--eye", "0,0,5", "--depth-bits", "12"],
        ),
        &["--depth-bits"],
    );
    let out = scratch("sizes").join("f.png");
    let out = out.to_str().unwrap();
    for size in ["0x10", "10", "9000x10"] {
        assert_one_line_error(
            &[
                "reference",
                "--eye",
                "0,1,9",
                "--target",
                "0,1,0",
                "--size",
                size,
                "--out",
                out,
            ],
            &["--size"],
        );
    }
    assert_one_line_error(
        &[
            "reference",
            "--eye",
            "0,1,9",
            "--target",
            "0,1,9",
            "--size",
            "8x8",
            "--out",
            out,
        ],
        &["coincide"],
    );
    assert_one_line_error(
        &[
            "reference",
            "--eye",
            "0,1,9",
            "--target",
            "0,1,0",
            "--fov",
            "200",
            "--size",
            "8x8",
            "--out",
            out,
        ],
        &["field of view"],
    );
}

#[test]
fn help_works_everywhere() {
    for args in [
        &["--help"][..],
        &["bake", "--help"],
        &["reference", "--help"],
        &["bench", "raytrace", "--help"],
    ] {
        let (code, stdout, _) = relief(args);
        assert_eq!(code, 0, "{args:?}");
        assert!(stdout.contains("Usage"), "{args:?}: {stdout}");
    }
}

#[test]
fn bench_raytrace_prints_the_promised_json() {
    let (code, stdout, stderr) = relief(&[
        "bench", "raytrace", "--scene", "default", "--object", "sphere", "--size", "32", "--runs", "1",
        "--json",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(stdout.trim()).expect("one JSON object");
    for key in [
        "triangles",
        "bvh_build_ms",
        "rays_per_s_1t",
        "rays_per_s_mt",
        "threads",
    ] {
        assert!(v[key].as_f64().is_some_and(|x| x > 0.0), "{key} in {stdout}");
    }
    assert_eq!(v["triangles"].as_u64(), Some(20480));
}
