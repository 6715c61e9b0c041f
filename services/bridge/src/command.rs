//! Remote commands: the JSON a client sends to `grains/<run>/control`, checked before anything
//! reaches the run. A command that fails here is answered with the reason and changes nothing.
//!
//! ```json
//! {"command": "pause"}            // also "resume", "stop", "snapshot", "checkpoint"
//! {"command": "set", "key": "gravity.y", "value": -9.81}
//! {"command": "set", "key": "wall.0.velocity.x", "value": 0.05}
//! ```

use grains_protocol::wire::{Command, Param};
use serde::Deserialize;

/// Longest command payload accepted [bytes]: every valid command fits in far less.
pub const MAX_COMMAND_BYTES: usize = 1024;

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

/// Parses and checks one command payload for a run whose scene has `walls` walls.
pub fn parse(payload: &[u8], walls: usize) -> Result<Checked, String> {
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
    let names = || Command::ALL.map(Command::name).join(", ");
    let command = Command::ALL
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
    let allowed = || {
        let walls = match walls {
            0 => String::new(),
            1 => ", wall.0.velocity.x|y|z".to_string(),
            n => format!(", wall.K.velocity.x|y|z (K < {n})"),
        };
        format!("gravity.x|y|z{walls}")
    };
    let key = raw.key.ok_or_else(|| format!("set: missing \"key\"; settable: {}", allowed()))?;
    let p = Param::parse(&key)
        .filter(|p| !matches!(p, Param::WallVelocity { wall, .. } if *wall >= walls))
        .ok_or_else(|| format!("set: {key:?} is not settable; settable: {}", allowed()))?;
    let (min, max, unit) = p.range();
    let value = raw
        .value
        .as_ref()
        .and_then(serde_json::Value::as_f64)
        .ok_or_else(|| format!("set {}: \"value\" must be a number in [{min}, {max}] {unit}", p.name()))?;
    if !(min..=max).contains(&value) {
        return Err(format!(
            "set {}: {} is outside [{min}, {max}] {unit}",
            p.name(),
            grains_protocol::number(value)
        ));
    }
    Ok(Checked {
        command,
        key: p.code(),
        value,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn good_commands_parse() {
        assert_eq!(parse(br#"{"command":"pause"}"#, 0).unwrap().command, Command::Pause);
        assert_eq!(parse(br#" {"command": "stop"} "#, 0).unwrap().command, Command::Stop);
        let c = parse(br#"{"command":"set","key":"gravity.y","value":-3.5}"#, 0).unwrap();
        assert_eq!((c.command, c.key, c.value), (Command::Set, 2, -3.5));
        let c = parse(br#"{"command":"set","key":"wall.1.velocity.x","value":0.5}"#, 2).unwrap();
        assert_eq!(c.key, Param::WallVelocity { wall: 1, axis: 0 }.code());
    }

    #[test]
    fn bad_commands_say_why() {
        let cases: [(&[u8], &str); 13] = [
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
            (
                br#"{"command":"set","key":"gravity.y","value":1e308}"#,
                "set gravity.y: 1e308 is outside",
            ),
            (br#"{"command":"set","key":"wall.2.velocity.x","value":1}"#, "not settable"),
            (
                br#"{"command":"set","key":"wall.0.velocity.x","value":11}"#,
                "outside [-10, 10] m/s",
            ),
        ];
        for (payload, want) in cases {
            let err = parse(payload, 2).unwrap_err();
            assert!(err.contains(want), "{:?}: {err}", String::from_utf8_lossy(payload));
        }
        let huge = vec![b' '; MAX_COMMAND_BYTES + 1];
        assert!(parse(&huge, 2).unwrap_err().contains("at most 1024 bytes"));
    }
}
