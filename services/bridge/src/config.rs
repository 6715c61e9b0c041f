//! What the bridge listens on and who may do what: the bridge's settings, the zenoh
//! configuration made of them (bridge and clients), and the key names of a run.

use anyhow::{Context, bail};
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// Default zenoh endpoint of a bridge: loopback only.
pub const DEFAULT_LISTEN: &str = "tcp/127.0.0.1:7447";

/// Key expressions of a run, the only place they are spelled.
pub mod keys {
    pub fn summary(run: &str) -> String {
        format!("grains/{run}/state/summary")
    }
    pub fn config(run: &str) -> String {
        format!("grains/{run}/state/config")
    }
    /// Decimated view of a solver's grains or points (`dem`, `mpm`).
    pub fn view(run: &str, role: &str) -> String {
        format!("grains/{run}/state/view/{role}")
    }
    pub fn state_all(run: &str) -> String {
        format!("grains/{run}/state/**")
    }
    pub fn control(run: &str) -> String {
        format!("grains/{run}/control")
    }
    pub fn alive(run: &str, who: &str) -> String {
        format!("grains/{run}/alive/{who}")
    }
    /// Liveliness tokens of every run's bridge (for `grains runs`).
    pub const ALL_BRIDGES: &str = "grains/*/alive/bridge";
    /// The run id in a key `grains/<run>/...`.
    pub fn run_of(key: &str) -> Option<&str> {
        key.strip_prefix("grains/")?.split('/').next()
    }
}

/// The bridge's settings: command-line flags, optionally a TOML file (`--config`) whose
/// values the flags override.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct BridgeConfig {
    /// zenoh endpoints to listen on.
    #[serde(default = "default_listen")]
    pub listen: Vec<String>,
    /// Whether remote clients may steer (pause, resume, stop, snapshot, set).
    #[serde(default)]
    pub steering: bool,
    /// Summaries per second at most (0: every macro-step).
    #[serde(default = "default_rate")]
    pub rate: f64,
    /// Access control: without it anyone who can reach the endpoint may read (and steer,
    /// if steering is on).
    #[serde(default)]
    pub auth: Option<Auth>,
    /// The live viewer (a web page served by the bridge); off without this table.
    #[serde(default)]
    pub view: Option<View>,
}

/// The live viewer's settings.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct View {
    /// Address of the page's HTTP server, `IP:PORT` (port 0: a free one); its WebSocket
    /// listens on a free port of the same IP.
    #[serde(default = "default_view_listen")]
    pub listen: String,
    /// With `[auth]`: the user the page reads (and steers) as; its password is read from
    /// `auth.users_file`.
    #[serde(default)]
    pub user: Option<String>,
}

fn default_view_listen() -> String {
    "127.0.0.1:0".to_string()
}

impl Default for View {
    fn default() -> Self {
        View {
            listen: default_view_listen(),
            user: None,
        }
    }
}

/// zenoh user/password authentication plus an access-control list built from it.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Auth {
    /// zenoh's dictionary file: one `user:password` per line.
    pub users_file: PathBuf,
    /// Users that may read the state (summaries, liveliness, queries).
    #[serde(default)]
    pub readers: Vec<String>,
    /// Users that may also send commands.
    #[serde(default)]
    pub steerers: Vec<String>,
}

fn default_listen() -> Vec<String> {
    vec![DEFAULT_LISTEN.to_string()]
}

fn default_rate() -> f64 {
    10.0
}

impl Default for BridgeConfig {
    fn default() -> Self {
        BridgeConfig {
            listen: default_listen(),
            steering: false,
            rate: default_rate(),
            auth: None,
            view: None,
        }
    }
}

impl BridgeConfig {
    /// Reads a TOML settings file; relative paths in it are relative to the file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("reading the bridge settings {}", path.display()))?;
        let mut c: BridgeConfig = toml::from_str(&text).map_err(|e| {
            let line = e.span().map(|s| text[..s.start].lines().count().max(1));
            anyhow::anyhow!(
                "{}{}: {}",
                path.display(),
                line.map_or(String::new(), |l| format!(":{l}")),
                e.message()
            )
        })?;
        if let Some(auth) = &mut c.auth
            && auth.users_file.is_relative()
        {
            auth.users_file = path.parent().unwrap_or(Path::new(".")).join(&auth.users_file);
        }
        c.check()?;
        Ok(c)
    }

    pub fn check(&self) -> anyhow::Result<()> {
        if self.listen.is_empty() {
            bail!("bridge: listen: at least one endpoint, e.g. {DEFAULT_LISTEN:?}");
        }
        for e in &self.listen {
            if !e.starts_with("tcp/") {
                bail!("bridge: listen: {e:?}: this build speaks TCP only (tcp/<address>:<port>)");
            }
        }
        if !(self.rate.is_finite() && self.rate >= 0.0) {
            bail!("bridge: rate: {} is not a rate; summaries per second, 0 for every step", self.rate);
        }
        if let Some(v) = &self.view {
            if v.listen.parse::<std::net::SocketAddr>().is_err() {
                bail!("bridge: view.listen: {:?} is not IP:PORT (e.g. \"127.0.0.1:8080\")", v.listen);
            }
            match (&self.auth, &v.user) {
                (Some(_), None) => bail!("bridge: view: with [auth], view.user says as whom the page reads (a reader or a steerer)"),
                (Some(a), Some(u)) if !a.readers.contains(u) && !a.steerers.contains(u) => {
                    bail!("bridge: view.user {u:?} is neither in auth.readers nor in auth.steerers")
                }
                (None, Some(u)) => bail!("bridge: view.user {u:?}: there is no [auth] to log in to"),
                _ => {}
            }
        }
        if let Some(a) = &self.auth {
            if !a.users_file.is_file() {
                bail!("bridge: auth.users_file: {} does not exist", a.users_file.display());
            }
            if a.readers.is_empty() && a.steerers.is_empty() {
                bail!("bridge: auth: no readers and no steerers: nobody could use the bridge");
            }
        }
        Ok(())
    }

    /// The zenoh configuration of the bridge of `run`: a peer that listens on the endpoints,
    /// connects nowhere and does not scout; with `auth`, user/password and a deny-by-default
    /// access-control list (readers: state and liveliness; steerers: also control).
    pub fn zenoh(&self, run: &str) -> anyhow::Result<zenoh::Config> {
        let mut c = zenoh::Config::default();
        let set =
            |c: &mut zenoh::Config, k: &str, v: &str| c.insert_json5(k, v).map_err(|e| anyhow::anyhow!("zenoh config {k} = {v}: {e}"));
        set(&mut c, "mode", r#""peer""#)?;
        set(&mut c, "listen/endpoints", &serde_json::to_string(&self.listen)?)?;
        set(&mut c, "connect/endpoints", "[]")?;
        set(&mut c, "scouting/multicast/enabled", "false")?;
        set(&mut c, "scouting/gossip/enabled", "false")?;
        if let Some(a) = &self.auth {
            set(
                &mut c,
                "transport/auth/usrpwd/dictionary_file",
                &serde_json::to_string(&a.users_file.display().to_string())?,
            )?;
            set(&mut c, "access_control", &self.acl(run).to_string())?;
        }
        Ok(c)
    }

    /// The access-control list of `run` (zenoh's `access_control` section). Seen from the
    /// bridge, a client's requests are ingress and what the bridge sends is egress: readers
    /// may subscribe and query the state and the liveliness tokens (in) and receive them
    /// (out), but cannot publish anything to other clients; steerers may also query the
    /// control key and receive its replies.
    pub fn acl(&self, run: &str) -> serde_json::Value {
        let Some(a) = &self.auth else {
            return serde_json::json!({ "enabled": false });
        };
        let read_keys = [
            keys::state_all(run),
            format!("grains/{run}/alive/**"),
            keys::ALL_BRIDGES.to_string(),
        ];
        let readers: Vec<&String> = a.readers.iter().chain(&a.steerers).collect();
        let mut subjects = vec![serde_json::json!({ "id": "readers", "usernames": readers })];
        let mut policies = vec![serde_json::json!({ "rules": ["read_in", "read_out"], "subjects": ["readers"] })];
        // zenoh refuses a subject without names.
        if !a.steerers.is_empty() {
            subjects.push(serde_json::json!({ "id": "steerers", "usernames": a.steerers }));
            policies.push(serde_json::json!({ "rules": ["steer_in", "steer_out"], "subjects": ["steerers"] }));
        }
        serde_json::json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": [
                { "id": "read_in", "permission": "allow", "flows": ["ingress"],
                  "messages": ["declare_subscriber", "query", "liveliness_query", "declare_liveliness_subscriber"],
                  "key_exprs": read_keys },
                { "id": "read_out", "permission": "allow", "flows": ["egress"],
                  "messages": ["put", "reply", "liveliness_token"],
                  "key_exprs": read_keys },
                { "id": "steer_in", "permission": "allow", "flows": ["ingress"],
                  "messages": ["query"], "key_exprs": [keys::control(run)] },
                { "id": "steer_out", "permission": "allow", "flows": ["egress"],
                  "messages": ["reply"], "key_exprs": [keys::control(run)] },
            ],
            "subjects": subjects,
            "policies": policies,
        })
    }

    /// What the bridge runs with, for its log and `bridge.json` (no passwords).
    pub fn effective(&self, run: &str) -> serde_json::Value {
        serde_json::json!({
            "run": run,
            "listen": self.listen,
            "steering": self.steering,
            "rate": self.rate,
            "view": self.view.as_ref().map(|v| serde_json::json!({ "listen": v.listen, "user": v.user })),
            "auth": self.auth.as_ref().map(|a| serde_json::json!({
                "users_file": a.users_file.display().to_string(),
                "readers": a.readers,
                "steerers": a.steerers,
            })),
            "keys": {
                "summary": keys::summary(run),
                "config": keys::config(run),
                "control": keys::control(run),
                "views": keys::view(run, "*"),
                "alive": keys::alive(run, "*"),
            },
        })
    }
}

/// The zenoh configuration of a remote client: connects to `endpoint` only, no scouting,
/// with credentials if given.
pub fn client(endpoint: &str, credentials: Option<(&str, &str)>) -> anyhow::Result<zenoh::Config> {
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| c.insert_json5(k, v).map_err(|e| anyhow::anyhow!("zenoh config {k} = {v}: {e}"));
    set(&mut c, "mode", r#""client""#)?;
    set(&mut c, "connect/endpoints", &serde_json::to_string(&[endpoint])?)?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    if let Some((user, password)) = credentials {
        set(&mut c, "transport/auth/usrpwd/user", &serde_json::to_string(user)?)?;
        set(&mut c, "transport/auth/usrpwd/password", &serde_json::to_string(password)?)?;
    }
    Ok(c)
}

/// The bridge's flags, shared by `grains run` (which passes them on) and `grains-bridge`.
#[derive(Clone, Debug, Default, clap::Args)]
pub struct BridgeArgs {
    /// Bridge settings file (TOML: listen, steering, rate, [auth]); the flags override its
    /// listen and rate and can turn steering on (not off). Default: the scene's [bridge]
    /// settings, if any.
    #[arg(long = "bridge-config", value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// zenoh endpoint the bridge listens on (repeatable) [default: tcp/127.0.0.1:7447].
    #[arg(long = "bridge-listen", value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Let remote clients pause, resume and stop the run (off: every command is refused).
    #[arg(long)]
    pub steering: bool,
    /// Summaries per second at most, 0 for every macro-step [default: 10].
    #[arg(long = "bridge-rate", value_name = "HZ")]
    pub rate: Option<f64>,
    /// Serve the live viewer (a web page; the bridge logs its URL).
    #[arg(long)]
    pub view: bool,
    /// The viewer page's address, IP:PORT [default: 127.0.0.1 on a free port]; implies --view.
    #[arg(long = "view-listen", value_name = "ADDR")]
    pub view_listen: Option<String>,
}

impl BridgeArgs {
    pub fn resolve(&self) -> anyhow::Result<BridgeConfig> {
        let mut c = match &self.config {
            Some(path) => BridgeConfig::load(path)?,
            None => BridgeConfig::default(),
        };
        if !self.listen.is_empty() {
            c.listen = self.listen.clone();
        }
        c.steering |= self.steering;
        if self.view || self.view_listen.is_some() {
            let v = c.view.get_or_insert_with(View::default);
            if let Some(l) = &self.view_listen {
                v.listen = l.clone();
            }
        }
        if let Some(rate) = self.rate {
            c.rate = rate;
        }
        c.check()?;
        Ok(c)
    }

    /// The same flags, for a child process.
    pub fn to_args(&self) -> Vec<String> {
        let mut out = Vec::new();
        if let Some(c) = &self.config {
            out.extend(["--bridge-config".to_string(), c.display().to_string()]);
        }
        for l in &self.listen {
            out.extend(["--bridge-listen".to_string(), l.clone()]);
        }
        if self.steering {
            out.push("--steering".into());
        }
        if let Some(r) = self.rate {
            out.extend(["--bridge-rate".to_string(), r.to_string()]);
        }
        if self.view {
            out.push("--view".into());
        }
        if let Some(l) = &self.view_listen {
            out.extend(["--view-listen".to_string(), l.clone()]);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Settings from TOML text with a users file beside them.
    fn settings(text: &str) -> anyhow::Result<BridgeConfig> {
        let dir = std::env::temp_dir().join(format!("grains-bridge-cfg-{}-{}", std::process::id(), text.len()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("users.txt"), "viewer:look\npilot:fly\n").unwrap();
        std::fs::write(dir.join("bridge.toml"), text).unwrap();
        let c = BridgeConfig::load(&dir.join("bridge.toml"));
        std::fs::remove_dir_all(&dir).unwrap();
        c
    }

    const AUTH: &str = "[auth]\nusers_file = \"users.txt\"\nreaders = [\"viewer\"]\nsteerers = [\"pilot\"]\n";

    #[test]
    fn the_viewer_settings_say_as_whom_the_page_acts() {
        let c = settings(&format!("{AUTH}[view]\nuser = \"viewer\"\n")).unwrap();
        assert_eq!(
            c.view,
            Some(View {
                listen: "127.0.0.1:0".into(),
                user: Some("viewer".into())
            })
        );
        for (text, says) in [
            (format!("{AUTH}[view]\n"), "view.user says as whom"),
            (
                format!("{AUTH}[view]\nuser = \"ghost\"\n"),
                "neither in auth.readers nor in auth.steerers",
            ),
            ("[view]\nuser = \"viewer\"\n".to_string(), "there is no [auth]"),
            ("[view]\nlisten = \"localhost\"\n".to_string(), "is not IP:PORT"),
        ] {
            let e = settings(&text).unwrap_err().to_string();
            assert!(e.contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn view_flags_turn_the_viewer_on_and_pass_to_the_bridge_process() {
        let args = BridgeArgs {
            view_listen: Some("127.0.0.1:8080".into()),
            ..Default::default()
        };
        assert_eq!(args.resolve().unwrap().view.unwrap().listen, "127.0.0.1:8080");
        assert_eq!(args.to_args(), ["--view-listen", "127.0.0.1:8080"]);
        let off = BridgeArgs::default();
        assert_eq!(off.resolve().unwrap().view, None);
        assert!(off.to_args().is_empty());
    }
}
