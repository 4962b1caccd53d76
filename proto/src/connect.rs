//! How clients and workers reach a server: one endpoint set-up for `http://` and
//! `https://` URLs (TLS with the system's roots, plus a CA file for self-signed
//! servers), TCP_NODELAY, bounded connect time.

use std::path::Path;
use std::time::Duration;

use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};

/// The endpoint for `url`; `ca` is a PEM file of extra trusted certificates (for a
/// server with a self-signed certificate). Errors name the problem.
pub fn endpoint(url: &str, ca: Option<&Path>) -> Result<Endpoint, String> {
    let mut endpoint = Endpoint::from_shared(url.to_string())
        .map_err(|e| format!("`{url}` is not a URL: {e}"))?
        .tcp_nodelay(true)
        .connect_timeout(Duration::from_secs(5));
    if url.starts_with("https://") || ca.is_some() {
        let mut tls = ClientTlsConfig::new().with_native_roots();
        if let Some(ca) = ca {
            let pem = std::fs::read(ca).map_err(|e| format!("{}: {e}", ca.display()))?;
            tls = tls.ca_certificate(Certificate::from_pem(pem));
        }
        endpoint = endpoint
            .tls_config(tls)
            .map_err(|e| format!("TLS for `{url}`: {e}"))?;
    }
    Ok(endpoint)
}
