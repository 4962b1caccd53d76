//! How clients and workers reach a server: one endpoint set-up for `http://` and
//! `https://` URLs (TLS with the system's roots, plus a CA file for self-signed
//! servers), TCP_NODELAY, bounded connect time.

use std::path::Path;
use std::time::Duration;

use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};

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
    #[error("TLS for `{url}`: {error}")]
    Tls {
        url: String,
        error: tonic::transport::Error,
    },
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
        .connect_timeout(Duration::from_secs(5));
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
