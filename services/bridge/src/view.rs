//! The live viewer: a web page that is a zenoh client of the run. The bridge serves the page
//! (`viewer/index.html` and its prebuilt script `viewer/dist/viewer.js`) over plain HTTP,
//! and hosts zenoh's remote-API plugin, which carries the page's zenoh calls over a
//! WebSocket. The plugin runs in a zenoh runtime of its own that joins the bridge as a
//! *client*, with the credentials of `view.user` when the bridge has `[auth]`: the page
//! reads and steers exactly as that user may, the bridge's access list deciding. (Hosted on
//! the bridge's own runtime, the plugin's sessions would be local and pass no access list.)

use crate::config::{BridgeConfig, View};
use anyhow::{Context, bail};
use std::io::{BufRead, BufReader, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};

const PAGE: &str = include_str!("../viewer/index.html");
const SCRIPT: &[u8] = include_bytes!("../viewer/dist/viewer.js");

/// The running viewer: kept alive for as long as the bridge serves.
pub struct Viewer {
    pub url: String,
    _runtime: tokio::runtime::Runtime,
    _zenoh: zenoh::internal::runtime::Runtime,
}

/// Starts the page's HTTP server and the remote-API runtime for `run`; the URL to open.
pub fn start(cfg: &BridgeConfig, view: &View, run: &str) -> anyhow::Result<Viewer> {
    let http = TcpListener::bind(&view.listen).with_context(|| format!("view.listen: cannot listen on {}", view.listen))?;
    let at = http.local_addr()?;
    // The WebSocket on a free port of the same address (the plugin takes no port 0).
    let ws = TcpListener::bind(SocketAddr::new(at.ip(), 0))?.local_addr()?;
    let endpoint = own_endpoint(cfg)?;
    let credentials = match (&cfg.auth, &view.user) {
        (Some(auth), Some(user)) => Some((user.clone(), password(&auth.users_file, user)?)),
        (Some(_), None) => bail!("view: the bridge has [auth]: say as which user the page reads (view.user)"),
        (None, _) => None,
    };
    let mut config = crate::config::client(&endpoint, credentials.as_ref().map(|(u, p)| (u.as_str(), p.as_str())))?;
    config
        .insert_json5(
            "plugins/remote_api",
            &serde_json::json!({ "websocket_port": ws.to_string() }).to_string(),
        )
        .map_err(|e| anyhow::anyhow!("zenoh config plugins/remote_api: {e}"))?;
    let runtime = tokio::runtime::Builder::new_multi_thread().worker_threads(1).enable_all().build()?;
    let zenoh = runtime.block_on(async {
        let mut plugins = zenoh::internal::plugins::PluginsManager::static_plugins_only();
        plugins.declare_static_plugin::<zenoh_plugin_remote_api::RemoteApiPlugin, &str>("remote_api", true);
        let mut rt = zenoh::internal::runtime::RuntimeBuilder::new(config)
            .plugins_manager(plugins)
            .build()
            .await
            .map_err(|e| anyhow::anyhow!("the viewer's zenoh runtime: {e}"))?;
        rt.start()
            .await
            .map_err(|e| anyhow::anyhow!("the viewer's zenoh runtime cannot reach the bridge at {endpoint}: {e}"))?;
        anyhow::Ok(rt)
    })?;
    let query = format!("?ws=ws://{ws}&run={run}");
    let url = format!("http://{at}/{query}");
    std::thread::Builder::new()
        .name("viewer-http".into())
        .spawn(move || serve_page(http, &query))?;
    Ok(Viewer {
        url,
        _runtime: runtime,
        _zenoh: zenoh,
    })
}

/// The bridge's own endpoint as a client reaches it (a wildcard address as loopback).
fn own_endpoint(cfg: &BridgeConfig) -> anyhow::Result<String> {
    let first = cfg.listen.first().context("bridge: no listen endpoint")?;
    Ok(first.replace("/0.0.0.0:", "/127.0.0.1:").replace("/[::]:", "/[::1]:"))
}

/// `user`'s password in zenoh's dictionary file (`user:password` per line).
fn password(users_file: &std::path::Path, user: &str) -> anyhow::Result<String> {
    let text = std::fs::read_to_string(users_file).with_context(|| format!("reading {}", users_file.display()))?;
    text.lines()
        .filter_map(|l| l.split_once(':'))
        .find(|(u, _)| u.trim() == user)
        .map(|(_, p)| p.trim().to_string())
        .with_context(|| format!("view.user {user:?} is not in {}", users_file.display()))
}

/// Answers GET / and GET /dist/viewer.js; anything else is 404. The page without its query
/// (`http://HOST:PORT/`, easier to type) is sent to the one with it. One connection at a
/// time: a page asks for two files once.
fn serve_page(http: TcpListener, query: &str) {
    for stream in http.incoming().flatten() {
        if let Err(e) = answer(stream, query) {
            tracing::debug!("viewer page: {e}");
        }
    }
}

fn answer(mut stream: TcpStream, query: &str) -> anyhow::Result<()> {
    stream.set_read_timeout(Some(std::time::Duration::from_secs(5)))?;
    let mut line = String::new();
    BufReader::new(&stream).read_line(&mut line)?;
    let target = line.split_whitespace().nth(1).unwrap_or("/");
    let (path, asked) = target.split_once('?').unwrap_or((target, ""));
    let (status, kind, body): (&str, &str, &[u8]) = match path {
        "/" | "/index.html" if !asked.contains("ws=") => ("302 Found", "text/plain", b"see Location"),
        "/" | "/index.html" => ("200 OK", "text/html; charset=utf-8", PAGE.as_bytes()),
        "/dist/viewer.js" => ("200 OK", "text/javascript; charset=utf-8", SCRIPT),
        _ => ("404 Not Found", "text/plain", b"not found"),
    };
    let location = if status.starts_with("302") {
        format!("Location: /{query}\r\n")
    } else {
        String::new()
    };
    write!(
        stream,
        "HTTP/1.1 {status}\r\n{location}Content-Type: {kind}\r\nContent-Length: {}\r\nCache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    stream.write_all(body)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    /// What the page server answers to `GET <target>`: status line, headers and body.
    fn get(target: &str) -> (String, String) {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let at = listener.local_addr().unwrap();
        let server = std::thread::spawn(move || {
            let (stream, _) = listener.accept().unwrap();
            answer(stream, "?ws=ws://127.0.0.1:9&run=r1").unwrap();
        });
        let mut c = TcpStream::connect(at).unwrap();
        write!(c, "GET {target} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        let mut reply = Vec::new();
        c.read_to_end(&mut reply).unwrap();
        server.join().unwrap();
        let reply = String::from_utf8_lossy(&reply).into_owned();
        let (head, body) = reply.split_once("\r\n\r\n").unwrap();
        (head.to_string(), body.to_string())
    }

    #[test]
    fn the_page_server_sends_the_page_its_script_and_nothing_else() {
        let (head, _) = get("/");
        assert!(
            head.starts_with("HTTP/1.1 302") && head.contains("Location: /?ws=ws://127.0.0.1:9&run=r1"),
            "{head}"
        );
        let (head, body) = get("/?ws=ws://127.0.0.1:9&run=r1");
        assert!(head.starts_with("HTTP/1.1 200") && head.contains("text/html"), "{head}");
        assert_eq!(body, PAGE);
        let (head, body) = get("/dist/viewer.js");
        assert!(head.starts_with("HTTP/1.1 200") && head.contains("text/javascript"), "{head}");
        assert_eq!(body.len(), SCRIPT.len());
        assert!(head.contains(&format!("Content-Length: {}", SCRIPT.len())), "{head}");
        for other in ["/../Cargo.toml", "/src/viewer.js", "/favicon.ico"] {
            assert!(get(other).0.starts_with("HTTP/1.1 404"), "{other}");
        }
    }

    #[test]
    fn a_password_is_read_from_the_users_file() {
        let dir = std::env::temp_dir().join(format!("grains-view-users-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("users.txt");
        std::fs::write(&file, "viewer:look\npilot: fly \n").unwrap();
        assert_eq!(password(&file, "viewer").unwrap(), "look");
        assert_eq!(password(&file, "pilot").unwrap(), "fly");
        let missing = password(&file, "ghost").unwrap_err().to_string();
        assert!(missing.contains("\"ghost\" is not in"), "{missing}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
