//! Generates the Rust code of `relief/v1/relief.proto` with the vendored protoc.

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut config = prost_build::Config::new();
    // protoc comes from the protoc-bin-vendored crate, never from the machine.
    config.protoc_executable(protoc_bin_vendored::protoc_bin_path()?);
    // A texture's planes are shared, not copied, by every message that carries them:
    // the server hands one cached texture to each client waiting for it.
    config.bytes([".relief.v1.ReliefTexture"]);
    let out = PathBuf::from(std::env::var("OUT_DIR")?);
    tonic_prost_build::configure()
        .file_descriptor_set_path(out.join("relief_descriptor.bin"))
        .compile_with_config(config, &["relief/v1/relief.proto"], &["."])?;
    Ok(())
}
