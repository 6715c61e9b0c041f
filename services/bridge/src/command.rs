//! Remote commands: the JSON a client sends to `grains/<run>/control`, checked before anything
//! reaches the run. A command that fails here is answered with the reason and changes nothing.
//!
//! ```json
//! {"command": "pause"}            // also "resume", "stop", "snapshot"
//! {"command": "set", "key": "gravity.y", "value": -9.81}
//! ```

use grains_protocol::wire::Command;
use serde::Deserialize;

/// Longest command payload accepted [bytes]: every valid command fits in far less.
pub const MAX_COMMAND_BYTES: usize = 1024;

/// A parameter that `set` may change: its wire key, its name and the values allowed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settable {
    pub key: u32,
    pub name: &'static str,
    pub min: f64,
    pub max: f64,
    pub unit: &'static str,
}

/// The whitelist of `set`. Keys are the wire codes of [`grains_protocol::wire::Control::key`].
pub const SETTABLE: [Settable; 3] = [
    Settable {
        key: 1,
        name: "gravity.x",
        min: -100.0,
        max: 100.0,
        unit: "m/s²",
    },
    Settable {
        key: 2,
        name: "gravity.y",
        min: -100.0,
        max: 100.0,
        unit: "m/s²",
    },
    Settable {
        key: 3,
        name: "gravity.z",
        min: -100.0,
        max: 100.0,
        unit: "m/s²",
    },
];

/// A checked command, ready for the wire.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Checked {
    pub command: Command,
    /// Wire key of `set` (0 otherwise) and its value.
    pub key: u32,
    pub value: f64,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    command: String,
    key: Option<String>,
    value: Option<serde_json::Value>,
}

/// Parses and checks one command payload.
pub fn parse(payload: &[u8]) -> Result<Checked, String> {
    if payload.len() > MAX_COMMAND_BYTES {
        return Err(format!(
            "payload of {} bytes; a command is a JSON object of at most {MAX_COMMAND_BYTES} bytes",
            payload.len()
        ));
    }
    let text = std::str::from_utf8(payload).map_err(|e| format!("payload is not UTF-8 ({e})"))?;
    let raw: Raw = serde_json::from_str(text).map_err(|e| {
        format!(
            "not a command ({e}); expected a JSON object like {{\"command\": \"pause\"}} or \
             {{\"command\": \"set\", \"key\": \"gravity.y\", \"value\": -9.81}}"
        )
    })?;
    let names = || {
        let all: Vec<_> = [Command::Pause, Command::Resume, Command::Stop, Command::Snapshot, Command::Set]
            .iter()
            .map(|c| c.name())
            .collect();
        all.join(", ")
    };
    let command = [Command::Pause, Command::Resume, Command::Stop, Command::Snapshot, Command::Set]
        .into_iter()
        .find(|c| c.name() == raw.command)
        .ok_or_else(|| format!("unknown command {:?}; allowed: {}", raw.command, names()))?;
    if command != Command::Set {
        if raw.key.is_some() || raw.value.is_some() {
            return Err(format!("{}: takes no key or value", command.name()));
        }
        return Ok(Checked {
            command,
            key: 0,
            value: 0.0,
        });
    }
    let allowed = || SETTABLE.iter().map(|s| s.name).collect::<Vec<_>>().join(", ");
    let key = raw.key.ok_or_else(|| format!("set: missing \"key\"; settable: {}", allowed()))?;
    let p = SETTABLE
        .iter()
        .find(|s| s.name == key)
        .ok_or_else(|| format!("set: {key:?} is not settable; settable: {}", allowed()))?;
    let value = raw
        .value
        .as_ref()
        .and_then(serde_json::Value::as_f64)
        .ok_or_else(|| format!("set {}: \"value\" must be a number in [{}, {}] {}", p.name, p.min, p.max, p.unit))?;
    if !(p.min..=p.max).contains(&value) {
        return Err(format!("set {}: {value} is outside [{}, {}] {}", p.name, p.min, p.max, p.unit));
    }
    Ok(Checked {
        command,
        key: p.key,
        value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn good_commands_parse() {
        assert_eq!(parse(br#"{"command":"pause"}"#).unwrap().command, Command::Pause);
        assert_eq!(parse(br#" {"command": "stop"} "#).unwrap().command, Command::Stop);
        let c = parse(br#"{"command":"set","key":"gravity.y","value":-3.5}"#).unwrap();
        assert_eq!((c.command, c.key, c.value), (Command::Set, 2, -3.5));
    }

    #[test]
    fn bad_commands_say_why() {
        let cases: [(&[u8], &str); 10] = [
            (b"", "not a command"),
            (b"pause", "not a command"),
            (b"\xff\xfe", "not UTF-8"),
            (br#"{"command":"jump"}"#, "unknown command \"jump\""),
            (br#"{"command":5}"#, "not a command"),
            (br#"{"command":"pause","value":1}"#, "takes no key or value"),
            (br#"{"command":"pause","extra":1}"#, "unknown field"),
            (br#"{"command":"set","key":"dt","value":1}"#, "\"dt\" is not settable"),
            (br#"{"command":"set","key":"gravity.y","value":"x"}"#, "must be a number"),
            (br#"{"command":"set","key":"gravity.y","value":1e9}"#, "outside [-100, 100]"),
        ];
        for (payload, want) in cases {
            let err = parse(payload).unwrap_err();
            assert!(err.contains(want), "{:?}: {err}", String::from_utf8_lossy(payload));
        }
        let huge = vec![b' '; MAX_COMMAND_BYTES + 1];
        assert!(parse(&huge).unwrap_err().contains("at most 1024 bytes"));
    }
}
