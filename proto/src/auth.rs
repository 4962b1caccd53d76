//! The bearer token clients and workers send (`authorization: Bearer TOKEN`).

use tonic::metadata::{Ascii, MetadataValue};
use tonic::{Request, Status};

/// A token that cannot be sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum TokenError {
    #[error("the token is empty")]
    Empty,
    #[error("the token holds characters not allowed in a header")]
    NotAHeader,
}

/// A client-side interceptor adding the token, when there is one, to every call.
#[derive(Debug, Clone, Default)]
pub struct BearerToken(Option<MetadataValue<Ascii>>);

impl BearerToken {
    /// From the shared secret; an error names the problem when it cannot be a header.
    pub fn new(token: Option<&str>) -> Result<BearerToken, TokenError> {
        token
            .map(|t| {
                if t.is_empty() {
                    return Err(TokenError::Empty);
                }
                format!("Bearer {t}").parse().map_err(|_| TokenError::NotAHeader)
            })
            .transpose()
            .map(BearerToken)
    }

    /// The header value, for servers to compare against.
    pub fn header(&self) -> Option<&MetadataValue<Ascii>> {
        self.0.as_ref()
    }
}

impl tonic::service::Interceptor for BearerToken {
    fn call(&mut self, mut request: Request<()>) -> Result<Request<()>, Status> {
        if let Some(token) = &self.0 {
            request.metadata_mut().insert("authorization", token.clone());
        }
        Ok(request)
    }
}
