//! The remote clients of `grains` (`runs`, `monitor`, `steer`): where the bridge is, who asks,
//! and how their answers are printed. The zenoh side is `grains_bridge::client`.

use grains_bridge::client::Endpoint;

/// Where the bridge is and who asks.
#[derive(clap::Args)]
pub struct Remote {
    /// The bridge's zenoh endpoint.
    #[arg(long, default_value = grains_bridge::config::DEFAULT_LISTEN)]
    pub connect: String,
    /// User name, if the bridge requires credentials; the password is read from the
    /// environment variable GRAINS_BRIDGE_PASSWORD.
    #[arg(long)]
    pub user: Option<String>,
}

impl Remote {
    pub fn endpoint(&self) -> anyhow::Result<Endpoint> {
        let credentials = match &self.user {
            Some(u) => {
                let p = std::env::var("GRAINS_BRIDGE_PASSWORD")
                    .map_err(|_| anyhow::anyhow!("--user {u}: set the password in the environment variable GRAINS_BRIDGE_PASSWORD"))?;
                Some((u.clone(), p))
            }
            None => None,
        };
        Ok(Endpoint {
            connect: self.connect.clone(),
            credentials,
        })
    }
}

/// `grains steer` words as the JSON command the bridge takes.
pub fn command_json(words: &[String]) -> anyhow::Result<String> {
    match words {
        [c] => Ok(serde_json::json!({ "command": c }).to_string()),
        [set, key, value] if set == "set" => {
            let v: f64 = value.parse().map_err(|_| anyhow::anyhow!("set {key}: {value:?} is not a number"))?;
            Ok(serde_json::json!({ "command": "set", "key": key, "value": v }).to_string())
        }
        _ => anyhow::bail!(
            "expected pause, resume, stop, snapshot, checkpoint or set KEY VALUE; got {:?}",
            words.join(" ")
        ),
    }
}

/// `grains steer`: sends the command; exit code 0 when applied (its acknowledgement printed),
/// 1 when refused (the reason on stderr).
pub fn steer(remote: &Remote, run: &str, words: &[String]) -> anyhow::Result<u8> {
    let json = command_json(words)?;
    match grains_bridge::client::steer(&remote.endpoint()?, run, json.as_bytes())? {
        Ok(ack) => {
            println!("{ack}");
            Ok(0)
        }
        Err(why) => {
            tracing::warn!("steer: refused: {why}");
            Ok(1)
        }
    }
}

/// `grains runs`: one line per run whose bridge answers at the endpoint.
pub fn list_runs(remote: &Remote) -> anyhow::Result<u8> {
    let ep = remote.endpoint()?;
    let runs = grains_bridge::client::runs(&ep, std::time::Duration::from_secs(2))?;
    if runs.is_empty() {
        println!("no run answers at {}", ep.connect);
    }
    for (id, latest) in runs {
        match latest {
            Some(v) => println!(
                "{id}  scene {}  step {}/{}  t = {:.4e} s{}",
                v["scene"].as_str().unwrap_or("?"),
                v["step"],
                v["steps"],
                v["time"].as_f64().unwrap_or(0.0),
                if v["paused"].as_bool() == Some(true) { "  (paused)" } else { "" }
            ),
            None => println!("{id}  (no step yet)"),
        }
    }
    Ok(0)
}
