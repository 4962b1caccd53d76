//! How clients and workers reach a server: one endpoint set-up for `http://` and
//! `https://` URLs (TLS with the system's roots, plus a CA file for self-signed
//! servers), TCP_NODELAY, bounded connect time.

use std::path::Path;
use std::time::Duration;

use tonic::transport::{Certificate, ClientTlsConfig, Endpoint};

/// The endpoint for `url`; `ca` is a PEM file of extra trusted certificates (for a
/// server with a self-signed certificate). Errors name the problem.
pub fn endpoint(url: &str, ca: Option<&Path>) -> Result<Endpoint, String> {
    let https = url.starts_with("https://");
    if !https && !url.starts_with("http://") {
        return Err(format!("server URL `{url}` must start with http:// or https://"));
    }
    if ca.is_some() && !https {
        return Err(format!(
            "a CA certificate is for https:// servers, and `{url}` is not one"
        ));
    }
    let mut endpoint = Endpoint::from_shared(url.to_string())
        .map_err(|e| format!("server URL `{url}` is not a URL: {e}"))?
        .tcp_nodelay(true)
        .connect_timeout(Duration::from_secs(5));
    if https {
        let mut tls = ClientTlsConfig::new().with_native_roots();
        if let Some(ca) = ca {
            let pem = std::fs::read(ca).map_err(|e| format!("CA certificate {}: {e}", ca.display()))?;
            tls = tls.ca_certificate(Certificate::from_pem(pem));
        }
        endpoint = endpoint
            .tls_config(tls)
            .map_err(|e| format!("TLS for `{url}`: {e}"))?;
    }
    Ok(endpoint)
}
