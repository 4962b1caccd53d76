//! Separate hosts on one machine: network namespaces, each joined to this one by a
//! veth pair, so that a test runs the server, workers and client each on its own
//! network stack and address, and nothing passes between them but through a
//! [`Relay`](crate::relay::Relay) this process runs — which delays, cuts and heals the
//! links. Nothing is forwarded by the kernel: the host's own settings are not touched.
//!
//! Needs root (`ip netns`): [`Hosts::create`] returns `None` otherwise, and the tests
//! say they skipped.

use std::process::Command;

/// A namespace per host, named `{prefix}-{k}`, with the veth pair `{prefix}{k}h` (this
/// side, `10.{net}.{k}.1/24`) and `{prefix}{k}n` (the host's, `10.{net}.{k}.2/24`);
/// deleted (with their pairs) when dropped.
pub struct Hosts {
    names: Vec<String>,
    net: u8,
}

/// Runs `ip` with `args`; whether it succeeded.
fn ip(args: &[&str]) -> bool {
    Command::new("ip")
        .args(args)
        .output()
        .is_ok_and(|out| out.status.success())
}

impl Hosts {
    /// `count` hosts named after `prefix` (at most 8 bytes: interface names are
    /// short), on the networks `10.{net}.{k}.0/24`; `None` when this process may not
    /// make namespaces (not root, or no `ip`).
    pub fn create(prefix: &str, net: u8, count: usize) -> Option<Hosts> {
        let mut hosts = Hosts {
            names: Vec::new(),
            net,
        };
        for k in 1..=count {
            let name = format!("{prefix}-{k}");
            // (A namespace left by a test that was killed goes first.)
            ip(&["netns", "del", &name]);
            if !ip(&["netns", "add", &name]) {
                return None;
            }
            hosts.names.push(name.clone());
            let (here, there) = (format!("{prefix}{k}h"), format!("{prefix}{k}n"));
            ip(&["link", "del", &here]);
            let joined = ip(&["link", "add", &here, "type", "veth", "peer", "name", &there])
                && ip(&["link", "set", &there, "netns", &name])
                && ip(&["addr", "add", &format!("10.{net}.{k}.1/24"), "dev", &here])
                && ip(&["link", "set", &here, "up"])
                && ip(&[
                    "-n",
                    &name,
                    "addr",
                    "add",
                    &format!("10.{net}.{k}.2/24"),
                    "dev",
                    &there,
                ])
                && ip(&["-n", &name, "link", "set", &there, "up"])
                && ip(&["-n", &name, "link", "set", "lo", "up"]);
            if !joined {
                return None;
            }
        }
        Some(hosts)
    }

    /// Host `k`'s (from 1) own address.
    pub fn address(&self, k: usize) -> String {
        format!("10.{}.{k}.2", self.net)
    }

    /// The address of this side of host `k`'s link: where a relay listens for it.
    pub fn gateway(&self, k: usize) -> String {
        format!("10.{}.{k}.1", self.net)
    }

    /// A command that runs the workspace's binary `name` on host `k` (as
    /// [`command`](crate::command) does here).
    pub fn command(&self, k: usize, name: &str) -> Command {
        let local = crate::command(name);
        let mut command = Command::new("ip");
        command
            .args(["netns", "exec", &self.names[k - 1]])
            .arg(local.get_program())
            .envs(local.get_envs().filter_map(|(key, value)| Some((key, value?))));
        command
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // (Deleting a namespace deletes its end of the pair, and so the pair.)
        for name in &self.names {
            ip(&["netns", "del", name]);
        }
    }
}
