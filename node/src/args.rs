//! Options every process shares, flattened into each binary's arguments (zenoh's `CommonArgs` idea).

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use crate::NodeError;

/// Command-line options common to every role.
#[derive(Debug, Clone, Args)]
pub struct NodeArgs {
    /// Run configuration (TOML, one table per crate; see deploy/configs/).
    #[arg(long, env = "SACLSP_CONFIG")]
    pub config: Option<PathBuf>,
    /// Run id: every key of this run lives under rl/<run-id>/.
    #[arg(long, env = "SACLSP_RUN_ID", default_value = "default")]
    pub run_id: String,
    /// This process's id within its role (executors: 0..N).
    #[arg(long, default_value_t = 0)]
    pub id: u32,
    /// zenoh endpoints to connect to, e.g. tcp/10.0.0.5:7447 (repeatable).
    #[arg(long)]
    pub connect: Vec<String>,
    /// zenoh endpoints to listen on, e.g. tcp/0.0.0.0:7447 (repeatable).
    #[arg(long)]
    pub listen: Vec<String>,
    /// zenoh session mode.
    #[arg(long, value_enum, default_value_t = ZenohMode::Peer)]
    pub mode: ZenohMode,
    /// Discover peers by UDP multicast (off by default: explicit endpoints are faster and predictable).
    #[arg(long)]
    pub multicast: bool,
    /// A zenoh JSON5 config file (TLS, access control, ...); the flags above are applied on top.
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// Extra zenoh config values as KEY:JSON5, e.g. 'transport/shared_memory/enabled:false'.
    #[arg(long = "zenoh-cfg", value_name = "KEY:VALUE")]
    pub zenoh_cfg: Vec<String>,
}

/// zenoh's session modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum, Default)]
pub enum ZenohMode {
    /// Talk to peers directly (a mesh): the data paths of one run.
    #[default]
    Peer,
    /// Talk only through the one router or peer connected to; fails fast when it is unreachable.
    Client,
    /// Forward for others (a rendezvous point for hosts that cannot reach each other directly).
    Router,
}

impl ZenohMode {
    fn as_str(self) -> &'static str {
        match self {
            ZenohMode::Peer => "peer",
            ZenohMode::Client => "client",
            ZenohMode::Router => "router",
        }
    }
}

/// How to open the zenoh session: the bus part of [`NodeArgs`], also built directly by tests.
#[derive(Debug, Clone, Default)]
pub struct BusConfig {
    /// Session mode.
    pub mode: ZenohMode,
    /// Endpoints to connect to.
    pub connect: Vec<String>,
    /// Endpoints to listen on.
    pub listen: Vec<String>,
    /// Multicast scouting on or off.
    pub multicast: bool,
    /// A zenoh config file to start from.
    pub zenoh_config: Option<PathBuf>,
    /// KEY:VALUE overrides applied last.
    pub overrides: Vec<String>,
}

impl BusConfig {
    /// A peer listening on a free loopback port and connecting to `connect`: what tests use.
    pub fn loopback(connect: Vec<String>) -> Self {
        Self { listen: vec!["tcp/127.0.0.1:0".into()], connect, ..Self::default() }
    }

    /// The zenoh configuration these options describe.
    pub fn to_zenoh(&self) -> Result<zenoh::Config, NodeError> {
        let mut config = match &self.zenoh_config {
            Some(path) => zenoh::Config::from_file(path).map_err(NodeError::zenoh)?,
            None => zenoh::Config::default(),
        };
        let set = |config: &mut zenoh::Config, key: &str, value: String| {
            config.insert_json5(key, &value).map_err(|e| NodeError::Zenoh(format!("{key} = {value}: {e}")))
        };
        set(&mut config, "mode", json_string(self.mode.as_str()))?;
        set(&mut config, "scouting/multicast/enabled", self.multicast.to_string())?;
        if !self.connect.is_empty() {
            set(&mut config, "connect/endpoints", json_list(&self.connect))?;
        }
        if !self.listen.is_empty() {
            set(&mut config, "listen/endpoints", json_list(&self.listen))?;
        }
        for entry in &self.overrides {
            let Some((key, value)) = entry.split_once(':') else {
                return Err(NodeError::Zenoh(format!("--zenoh-cfg {entry:?} is not KEY:VALUE")));
            };
            set(&mut config, key, value.to_string())?;
        }
        Ok(config)
    }
}

impl From<&NodeArgs> for BusConfig {
    fn from(args: &NodeArgs) -> Self {
        Self {
            mode: args.mode,
            connect: args.connect.clone(),
            listen: args.listen.clone(),
            multicast: args.multicast,
            zenoh_config: args.zenoh_config.clone(),
            overrides: args.zenoh_cfg.clone(),
        }
    }
}

fn json_string(s: &str) -> String {
    format!("\"{}\"", s.replace('\\', "\\\\").replace('"', "\\\""))
}

fn json_list(items: &[String]) -> String {
    format!("[{}]", items.iter().map(|s| json_string(s)).collect::<Vec<_>>().join(","))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flags_become_zenoh_config() {
        let cfg = BusConfig {
            mode: ZenohMode::Client,
            connect: vec!["tcp/127.0.0.1:7447".into()],
            overrides: vec!["transport/shared_memory/enabled:false".into()],
            ..BusConfig::default()
        };
        let z = cfg.to_zenoh().unwrap();
        assert_eq!(z.get_json("mode").unwrap(), "\"client\"");
        assert!(z.get_json("connect/endpoints").unwrap().contains("tcp/127.0.0.1:7447"));
        assert_eq!(z.get_json("scouting/multicast/enabled").unwrap(), "false");
    }

    #[test]
    fn a_malformed_override_is_an_error() {
        let cfg = BusConfig { overrides: vec!["no-colon".into()], ..BusConfig::default() };
        assert!(cfg.to_zenoh().is_err());
        let cfg = BusConfig { overrides: vec!["mode:\"sideways\"".into()], ..BusConfig::default() };
        assert!(cfg.to_zenoh().is_err());
    }
}
