//! How clients and workers reach a server: one endpoint set-up for `http://` and
//! `https://` URLs (TLS with the system's roots, plus a CA file for self-signed
//! servers), TCP_NODELAY, bounded connect time, and HTTP/2 keepalive so that a peer
//! gone without a word is noticed.

use std::path::Path;
use std::time::Duration;

use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};

/// Every connection, both ways and idle or not, is pinged this often over HTTP/2 …
pub const KEEPALIVE_INTERVAL: Duration = Duration::from_secs(2);

/// … and ended when a ping is not answered within this: a peer gone without closing
/// (a cut link, a lost machine) is noticed within the two together — 4 s — where a
/// stream waited on it for ever. (Seconds, not less: a 250 ms round trip with loss
/// must not count as gone.)
pub const KEEPALIVE_TIMEOUT: Duration = Duration::from_secs(2);

/// Why no endpoint can be made for a server URL; each names the URL or file.
#[derive(Debug, thiserror::Error)]
pub enum EndpointError {
    #[error("server URL `{0}` must start with http:// or https://")]
    Scheme(String),
    #[error("a CA certificate is for https:// servers, and `{0}` is not one")]
    CaWithoutTls(String),
    #[error("server URL `{url}` is not a URL: {error}")]
    NotAUrl {
        url: String,
        error: tonic::transport::Error,
    },
    /// (The I/O error is part of the message, not a `source`: printed with `{:#}` it
    /// would show twice.)
    #[error("CA certificate {}: {error}", path.display())]
    CaFile {
        path: std::path::PathBuf,
        error: std::io::Error,
    },
    #[error(
        "the token would cross the network in clear to `{0}`: use an https:// server \
         (or --allow-insecure, on a network where every host is trusted)"
    )]
    TokenInClear(String),
    #[error("TLS for `{url}`: {error}")]
    Tls {
        url: String,
        error: tonic::transport::Error,
    },
}

/// What went wrong reaching a server, in full: a transport error's own message is
/// only "transport error", and the cause — a refused connection, a certificate the
/// TLS layer rejects and why — lies down its chain of sources. A certificate problem
/// gets a line on what to do about it.
pub fn explain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut next = Some(error);
    while let Some(e) = next {
        let text = e.to_string();
        if !parts.iter().any(|p| p.contains(&text)) {
            parts.push(text);
        }
        next = e.source();
    }
    let mut message = parts.join(": ");
    let hints = [
        (
            "CaUsedAsEndEntity",
            "the server's certificate is marked as a CA (basicConstraints CA:TRUE): give the server a leaf certificate (CA:FALSE), signed by that CA or self-signed",
        ),
        (
            "UnknownIssuer",
            "the server's certificate is signed by no CA this side trusts: pass it (or its CA) with --tls-ca",
        ),
        (
            "NotValidForName",
            "the server's certificate does not name the host in the URL: use a name or address it lists (subjectAltName)",
        ),
        ("Expired", "the server's certificate has expired"),
    ];
    for (symptom, hint) in hints {
        if message.contains(symptom) {
            message = format!("{message} — {hint}");
        }
    }
    message
}

/// Refuses to send a credential unencrypted beyond this machine: with a `token`, an
/// `http://` `url` must name a loopback address (`localhost`, `127.0.0.0/8`, `::1`)
/// unless `allow_insecure`. (Anyone on the path could read it and act as its holder.)
pub fn refuse_token_in_clear(
    url: &str,
    token: Option<&str>,
    allow_insecure: bool,
) -> Result<(), EndpointError> {
    let Some(rest) = url.strip_prefix("http://") else {
        return Ok(());
    };
    if token.is_none() || allow_insecure {
        return Ok(());
    }
    let authority = rest.split(['/', '?', '#']).next().unwrap_or_default();
    let authority = authority.rsplit_once('@').map_or(authority, |(_, host)| host);
    let host = match authority.strip_prefix('[') {
        Some(bracketed) => bracketed.split(']').next().unwrap_or_default(),
        None => authority.split(':').next().unwrap_or_default(),
    };
    let loopback = host.eq_ignore_ascii_case("localhost")
        || host.parse::<std::net::IpAddr>().is_ok_and(|ip| ip.is_loopback());
    if loopback {
        Ok(())
    } else {
        Err(EndpointError::TokenInClear(url.to_string()))
    }
}

/// The endpoint for `url`; `ca` is a PEM file of extra trusted certificates (for a
/// server with a self-signed certificate). Errors name the problem.
pub fn endpoint(url: &str, ca: Option<&Path>) -> Result<Endpoint, EndpointError> {
    let https = url.starts_with("https://");
    if !https && !url.starts_with("http://") {
        return Err(EndpointError::Scheme(url.to_string()));
    }
    if ca.is_some() && !https {
        return Err(EndpointError::CaWithoutTls(url.to_string()));
    }
    let mut endpoint = Endpoint::from_shared(url.to_string())
        .map_err(|error| EndpointError::NotAUrl {
            url: url.to_string(),
            error,
        })?
        .tcp_nodelay(true)
        .connect_timeout(Duration::from_secs(5))
        .http2_keep_alive_interval(KEEPALIVE_INTERVAL)
        .keep_alive_timeout(KEEPALIVE_TIMEOUT)
        .keep_alive_while_idle(true);
    if https {
        let mut tls = ClientTlsConfig::new().with_native_roots();
        if let Some(ca) = ca {
            let pem = std::fs::read(ca).map_err(|error| EndpointError::CaFile {
                path: ca.to_path_buf(),
                error,
            })?;
            tls = tls.ca_certificate(Certificate::from_pem(pem));
        }
        endpoint = endpoint.tls_config(tls).map_err(|error| EndpointError::Tls {
            url: url.to_string(),
            error,
        })?;
    }
    Ok(endpoint)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_token_goes_in_clear_only_to_this_machine() {
        let sent =
            |url: &str, token: Option<&str>, allow: bool| refuse_token_in_clear(url, token, allow).is_ok();
        for url in [
            "http://127.0.0.1:7411",
            "http://localhost:7411/",
            "http://[::1]:7411",
            "http://127.9.9.9",
            "https://10.0.0.5:7411",
        ] {
            assert!(sent(url, Some("t"), false), "{url}");
        }
        for url in [
            "http://10.0.0.5:7411",
            "http://relief.example:7411",
            "http://[2001:db8::1]:1",
            "http://127.0.0.1.evil.example",
        ] {
            assert!(!sent(url, Some("t"), false), "{url}");
            assert!(sent(url, Some("t"), true) && sent(url, None, false), "{url}");
        }
    }
}
