//! The metrics endpoint the server and the workers share (`--metrics-listen`): every
//! request over HTTP/1 is answered with the registry's metrics in the OpenMetrics text
//! format, which Prometheus scrapes — collected at that moment from the process's own
//! counters (see each binary's collector), so nothing is counted twice.
//!
//! The HTTP is hyper's, the one tonic already runs on; the encoding is the Prometheus
//! project's `prometheus-client`.
//!
//! ```no_run
//! # async fn example() -> std::io::Result<()> {
//! use prometheus_client::registry::Registry;
//! let listener = tokio::net::TcpListener::bind("127.0.0.1:9464").await?;
//! let registry = Registry::with_prefix("relief_example");
//! tokio::spawn(relief_proto::metrics::serve(listener, std::sync::Arc::new(registry)));
//! # Ok(()) }
//! ```

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use http_body_util::Full;
use hyper::body::{Bytes, Incoming};
use hyper::{Request, Response};
use hyper_util::rt::{TokioIo, TokioTimer};
use prometheus_client::encoding::{DescriptorEncoder, EncodeMetric};
use prometheus_client::metrics::MetricType;
use prometheus_client::metrics::counter::ConstCounter;
use prometheus_client::metrics::gauge::ConstGauge;
use prometheus_client::registry::Registry;

/// A scraper that has not sent its request's headers within this is cut off: the
/// endpoint holds no connection for one that never speaks.
pub const HEADER_READ_TIMEOUT: Duration = Duration::from_secs(5);

/// The content type of the OpenMetrics text format.
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// Answers every HTTP/1 request on `listener` with `registry`'s metrics, until the
/// task is dropped.
pub async fn serve(listener: tokio::net::TcpListener, registry: Arc<Registry>) {
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _)) => stream,
            Err(e) => {
                // (Out of descriptors: wait rather than spin.)
                tracing::warn!("metrics endpoint: accepting: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let registry = registry.clone();
        tokio::spawn(async move {
            let answer = hyper::service::service_fn(move |_: Request<Incoming>| {
                let registry = registry.clone();
                async move { Ok::<_, Infallible>(scrape(&registry)) }
            });
            let served = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_READ_TIMEOUT)
                .serve_connection(TokioIo::new(stream), answer)
                .await;
            if let Err(e) = served {
                tracing::debug!("metrics endpoint: {e}");
            }
        });
    }
}

/// The registry's metrics as an HTTP response.
fn scrape(registry: &Registry) -> Response<Full<Bytes>> {
    let mut text = String::new();
    match prometheus_client::encoding::text::encode(&mut text, registry) {
        Ok(()) => Response::builder()
            .header(hyper::header::CONTENT_TYPE, CONTENT_TYPE)
            .body(Full::new(Bytes::from(text))),
        Err(_) => Response::builder()
            .status(hyper::StatusCode::INTERNAL_SERVER_ERROR)
            .body(Full::new(Bytes::from("encoding the metrics failed\n"))),
    }
    .unwrap_or_else(|_| Response::new(Full::new(Bytes::new())))
}

/// Writes one metric without labels: `kind` is a counter or a gauge.
pub fn encode_one(
    encoder: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    kind: MetricType,
    value: u64,
) -> Result<(), std::fmt::Error> {
    let metric = encoder.encode_descriptor(name, help, None, kind)?;
    match kind {
        MetricType::Counter => ConstCounter::new(value).encode(metric),
        _ => ConstGauge::new(value as i64).encode(metric),
    }
}

/// Writes one metric over the values of one label: `(label value, value)` each.
pub fn encode_by(
    encoder: &mut DescriptorEncoder,
    (name, help, kind): (&str, &str, MetricType),
    label: &str,
    values: &[(&str, u64)],
) -> Result<(), std::fmt::Error> {
    let mut metric = encoder.encode_descriptor(name, help, None, kind)?;
    for &(key, value) in values {
        let labels = [(label, key)];
        let one = metric.encode_family(&labels)?;
        match kind {
            MetricType::Counter => ConstCounter::new(value).encode(one)?,
            _ => ConstGauge::new(value as i64).encode(one)?,
        }
    }
    Ok(())
}

/// Writes a histogram from its buckets' own counts: `counts[i]` observations at most
/// `bounds[i]` (and above the bound before); one count more than bounds, those above
/// the last. `sum` is the observations' sum, in the bounds' unit.
pub fn encode_histogram(
    encoder: &mut DescriptorEncoder,
    name: &str,
    help: &str,
    (bounds, counts, sum): (&[f64], &[u64], f64),
) -> Result<(), std::fmt::Error> {
    let mut metric = encoder.encode_descriptor(name, help, None, MetricType::Histogram)?;
    let buckets: Vec<(f64, u64)> = bounds
        .iter()
        .copied()
        .chain(std::iter::once(f64::MAX))
        .zip(counts.iter().copied())
        .collect();
    let count = counts.iter().sum();
    metric.encode_histogram::<prometheus_client::encoding::NoLabelSet>(sum, count, &buckets, None)
}
