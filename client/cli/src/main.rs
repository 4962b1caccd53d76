//! `relief`: the client command line — glue that brings the renderer, the lab and the
//! impostor client together, one module per subcommand in `commands/`. The work is in
//! the libraries; each command parses its flags, calls them, and writes or prints what
//! they measured.
//!
//! Quiet by default (warnings only); `RUST_LOG=info` or `debug` for more. Errors print
//! one line, `error: …`, and exit non-zero.

mod args;
mod commands;
mod processes;
mod progress;
mod warp_files;
mod window;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "relief",
    version,
    about = "Relief impostors: bake relief textures, render references, benchmark"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// The loopback demo: server and workers on 127.0.0.1, a camera flight with impostors.
    Demo(commands::demo::DemoArgs),
    /// The same client flight against a remote server (`--server URL` required).
    Render(commands::demo::DemoArgs),
    /// Ray-trace the relief texture of one object for an eye.
    Bake(commands::bake::BakeArgs),
    /// Ray-trace a reference frame of the whole scene (per-pixel Phong).
    Reference(commands::reference::ReferenceArgs),
    /// One composited frame (geometry + impostors) and its speed against all geometry.
    Frame(commands::frame::FrameArgs),
    /// Many simulated clients against one server: latency, stalls and image error for
    /// each error tolerance (impostor lifetime).
    Load(commands::load::LoadArgs),
    /// Measurements written as CSV, JSON and plots.
    #[command(subcommand)]
    Report(commands::report::ReportCommand),
    /// Benchmarks that print numbers.
    #[command(subcommand)]
    Bench(commands::bench::BenchCommand),
}

fn main() -> ExitCode {
    relief_startup::run(|cli: Cli| match cli.command {
        Command::Demo(args) => commands::demo::run(args),
        Command::Render(args) if args.server.is_none() => Err(anyhow::anyhow!(
            "render needs --server URL (or RELIEF_SERVER); `relief demo` starts its own"
        )),
        Command::Render(args) => commands::demo::run(args),
        Command::Bake(args) => commands::bake::run(args),
        Command::Reference(args) => commands::reference::run(args),
        Command::Frame(args) => commands::frame::run(args),
        Command::Load(args) => commands::load::run(args),
        Command::Report(command) => commands::report::run(command),
        Command::Bench(command) => commands::bench::run(command),
    })
}
