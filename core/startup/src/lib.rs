//! What every Relief binary (`relief`, `relief-server`, `relief-worker`) does the same
//! way at start-up: parse arguments with one-line errors (exit 2), log quietly unless
//! `RUST_LOG` asks for more, and end with `error: …` on one line and exit 1 on failure.
//!
//! The one function is [`run`], a binary's whole `main`:
//!
//! ```no_run
//! #[derive(clap::Parser)]
//! struct Args {
//!     #[arg(long)]
//!     name: String,
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     relief_startup::run(|args: Args| {
//!         anyhow::ensure!(!args.name.is_empty(), "--name is empty");
//!         Ok(())
//!     })
//! }
//! ```

use std::io::IsTerminal;
use std::process::ExitCode;

/// A binary's `main`: parses the arguments (`parse`), starts logging, runs `body` and
/// ends with its outcome (`finish`).
pub fn run<T: clap::Parser>(body: impl FnOnce(T) -> anyhow::Result<()>) -> ExitCode {
    let args = match parse::<T>() {
        Ok(args) => args,
        Err(code) => return code,
    };
    init_logging();
    finish(body(args))
}

/// Parses the command line. On bad arguments prints the first line of clap's message
/// (it names the problem) and returns exit code 2; `--help`/`--version` print and
/// return success.
fn parse<T: clap::Parser>() -> Result<T, ExitCode> {
    match T::try_parse() {
        Ok(args) => Ok(args),
        Err(e) if e.use_stderr() => {
            let text = e.render().to_string();
            eprintln!("{}", text.lines().next().unwrap_or("error: bad arguments"));
            Err(ExitCode::from(2))
        }
        Err(e) => {
            let _ = e.print();
            Err(ExitCode::SUCCESS)
        }
    }
}

/// Logs to stderr: warnings by default, `RUST_LOG` for more; colours only on a
/// terminal.
fn init_logging() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
}

/// Ends a binary: success, or `error: …` on one line and exit code 1.
fn finish(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
