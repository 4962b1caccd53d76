//! Who is calling: each credential (a bearer token) is a client's or a worker's, never
//! both, and the server knows a caller only by it — never by a field the caller sends.
//!
//! # Roles
//!
//! - A **client** uploads scenes, asks for textures and withdraws them; its requests
//!   and scenes are its own: another credential can neither see nor withdraw them.
//! - A **worker** opens a session, takes jobs and answers for those leased to it; it
//!   reads a scene only while it holds a job on it.
//!
//! A server started with no credential at all serves everyone as one caller with both
//! roles (the loopback demo); `--token`, the single shared secret, is such a caller
//! too, for set-ups that trust every holder.
//!
//! ```
//! use relief_server::identity::{Credentials, Role};
//!
//! let credentials = Credentials::new(&["client-secret".into()], &["worker-secret".into()], None)?;
//! let client = credentials.caller(Some("Bearer client-secret")).expect("a client");
//! assert!(client.may(Role::Client) && !client.may(Role::Worker));
//! assert!(credentials.caller(Some("Bearer guess")).is_none());
//! # Ok::<(), relief_server::identity::CredentialError>(())
//! ```

use std::collections::HashMap;
use std::sync::Arc;

use tonic::{Request, Status};

/// What a credential may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    Client,
    Worker,
}

impl std::fmt::Display for Role {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Role::Client => "client",
            Role::Worker => "worker",
        })
    }
}

/// An authenticated caller: a name for logs and for scoping what it owns (`client-2`,
/// `worker-1`, `shared`, `anyone`; never the secret), and its roles.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Caller {
    pub name: Arc<str>,
    client: bool,
    worker: bool,
}

impl Caller {
    /// Whether it may act as `role`.
    pub fn may(&self, role: Role) -> bool {
        match role {
            Role::Client => self.client,
            Role::Worker => self.worker,
        }
    }

    /// PERMISSION_DENIED unless it may act as `role`.
    pub fn require(&self, role: Role) -> Result<(), Status> {
        if self.may(role) {
            Ok(())
        } else {
            Err(Status::permission_denied(format!(
                "this credential is not a {role}'s (it is `{}`'s)",
                self.name
            )))
        }
    }

    /// The caller of a request that passed [`Credentials::interceptor`].
    pub fn of<T>(request: &Request<T>) -> Result<Caller, Status> {
        request
            .extensions()
            .get::<Caller>()
            .cloned()
            .ok_or_else(|| Status::internal("the request was not authenticated"))
    }
}

/// A credential the server cannot take; each names the flag or file.
#[derive(Debug, thiserror::Error)]
pub enum CredentialError {
    #[error("{0}: a token is empty")]
    Empty(String),
    #[error("{0}: a token holds characters not allowed in a header")]
    NotAHeader(String),
    #[error("one token is given both as a client's and as a worker's: each credential has one role")]
    BothRoles,
    #[error("--token cannot be combined with client or worker tokens: give every holder its own")]
    SharedAndSeparate,
    #[error("tokens file {}: {error}", path.display())]
    File {
        path: std::path::PathBuf,
        error: std::io::Error,
    },
}

/// The tokens one line each in `path` (blank lines and `#` comments skipped).
pub fn read_tokens_file(path: &std::path::Path) -> Result<Vec<String>, CredentialError> {
    let text = std::fs::read_to_string(path).map_err(|error| CredentialError::File {
        path: path.to_path_buf(),
        error,
    })?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(String::from)
        .collect())
}

/// Every credential the server accepts, by its `authorization` header.
#[derive(Debug, Clone)]
pub struct Credentials {
    /// `None`: no credential is asked for; everyone is [`Credentials::open`]'s caller.
    by_header: Option<HashMap<String, Caller>>,
}

impl Credentials {
    /// From the client tokens, the worker tokens and the old shared `--token` (both
    /// roles, one caller). Nothing at all: an open server.
    pub fn new(
        clients: &[String],
        workers: &[String],
        shared: Option<&str>,
    ) -> Result<Credentials, CredentialError> {
        if clients.is_empty() && workers.is_empty() && shared.is_none() {
            return Ok(Credentials { by_header: None });
        }
        if shared.is_some() && !(clients.is_empty() && workers.is_empty()) {
            return Err(CredentialError::SharedAndSeparate);
        }
        let mut by_header = HashMap::new();
        let mut add = |flag: &str, token: &str, caller: Caller| {
            if token.is_empty() {
                return Err(CredentialError::Empty(flag.into()));
            }
            let header = format!("Bearer {token}");
            if header
                .parse::<tonic::metadata::MetadataValue<tonic::metadata::Ascii>>()
                .is_err()
            {
                return Err(CredentialError::NotAHeader(flag.into()));
            }
            match by_header.insert(header, caller.clone()) {
                Some(earlier) if earlier.client != caller.client => Err(CredentialError::BothRoles),
                _ => Ok(()),
            }
        };
        if let Some(token) = shared {
            add("--token", token, caller("shared", true, true))?;
        }
        for (k, token) in clients.iter().enumerate() {
            add(
                "client token",
                token,
                caller(&format!("client-{}", k + 1), true, false),
            )?;
        }
        for (k, token) in workers.iter().enumerate() {
            add(
                "worker token",
                token,
                caller(&format!("worker-{}", k + 1), false, true),
            )?;
        }
        Ok(Credentials {
            by_header: Some(by_header),
        })
    }

    /// Whether any credential is asked for.
    pub fn required(&self) -> bool {
        self.by_header.is_some()
    }

    /// The caller an `authorization` header names, if any (every caller, with or
    /// without one, on an open server).
    pub fn caller(&self, header: Option<&str>) -> Option<Caller> {
        match &self.by_header {
            None => Some(caller("anyone", true, true)),
            Some(by_header) => by_header.get(header?).cloned(),
        }
    }

    /// A server-side interceptor: UNAUTHENTICATED without a known credential,
    /// PERMISSION_DENIED for one that may not act as `role` (`None`: any role, each
    /// method then checks its own); the [`Caller`] goes into the request's extensions.
    pub fn interceptor(
        &self,
        role: Option<Role>,
    ) -> impl Fn(Request<()>) -> Result<Request<()>, Status> + Clone + use<> {
        let credentials = self.clone();
        move |mut request: Request<()>| {
            let header = request
                .metadata()
                .get("authorization")
                .and_then(|v| v.to_str().ok());
            let caller = credentials
                .caller(header)
                .ok_or_else(|| Status::unauthenticated("missing or wrong `authorization: Bearer` token"))?;
            if let Some(role) = role {
                caller.require(role)?;
            }
            request.extensions_mut().insert(caller);
            Ok(request)
        }
    }
}

fn caller(name: &str, client: bool, worker: bool) -> Caller {
    Caller {
        name: name.into(),
        client,
        worker,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_credential_has_its_roles_and_nothing_else_gets_in() {
        let c = Credentials::new(&["c1".into(), "c2".into()], &["w1".into()], None).expect("credentials");
        let client = c.caller(Some("Bearer c2")).expect("client");
        assert_eq!(&*client.name, "client-2");
        assert!(client.may(Role::Client) && !client.may(Role::Worker));
        let worker = c.caller(Some("Bearer w1")).expect("worker");
        assert!(worker.may(Role::Worker) && !worker.may(Role::Client));
        assert!(c.caller(Some("Bearer w2")).is_none());
        assert!(c.caller(Some("c1")).is_none());
        assert!(c.caller(None).is_none());
        let open = Credentials::new(&[], &[], None).expect("open");
        assert!(!open.required());
        let anyone = open.caller(None).expect("anyone");
        assert!(anyone.may(Role::Client) && anyone.may(Role::Worker));
    }

    #[test]
    fn bad_credentials_are_refused_naming_the_problem() {
        let err = |c: &[&str], w: &[&str], s: Option<&str>| {
            let own = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
            Credentials::new(&own(c), &own(w), s)
                .expect_err("refused")
                .to_string()
        };
        assert!(err(&["same"], &["same"], None).contains("both"));
        assert!(err(&[""], &[], None).contains("empty"));
        assert!(err(&["a\nb"], &[], None).contains("header"));
        assert!(err(&["a"], &[], Some("s")).contains("--token"));
    }
}
