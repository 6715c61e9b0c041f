"""Checkpoints: protocol/README.md §6.4.

A participant writes `<out-dir>/checkpoints/<step, 10 digits>/<role>.bin` after a checkpoint
step and before its summary of that step: a 48-byte header (magic, format, role, scene hash,
step, payload length, payload checksum) and its own payload. Resumed with `--resume DIR`, it
reads the step from `DIR/manifest.json` and its payload back from its file.
"""

import ctypes
import json
import os
import struct

from . import wire
from .participant import Halt

MAGIC = b"GRAINSCP"
FORMAT = 1
#: magic, format, role, scene hash, step, payload length, payload checksum.
HEADER = struct.Struct("<8sIIQQQQ")
ROLE_NAMES = {wire.DEM: "dem", wire.MPM: "mpm", wire.COUPLER: "coupler", wire.ORACLE: "oracle"}


def due(scene, step, asked=False):
    """§6.4: a checkpoint after `step`: the scene's cadence (never after the last step), or
    asked for by the step's begin (`STEP_CHECKPOINT`) or a `checkpoint` command."""
    every = scene.checkpoint_every
    return asked or (every > 0 and step % every == 0 and step < scene.steps)


def payload_checksum(payload):
    """§4's checksum over the payload's 8-byte words, the last one padded with zeros."""
    padded = payload + bytes(-len(payload) % 8)
    buf = ctypes.create_string_buffer(padded, max(len(padded), 8))
    return wire.checksum(ctypes.addressof(buf), len(padded))


def write(out_dir, role, scene_hash, step, payload):
    """Writes this role's checkpoint after `step` whole or not at all (temporary file,
    synced, renamed)."""
    if out_dir is None:
        raise Halt(f"a checkpoint is due after step {step}, but no --out-dir was given to write it in")
    folder = os.path.join(out_dir, "checkpoints", f"{step:010d}")
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, f"{ROLE_NAMES[role]}.bin")
    header = HEADER.pack(MAGIC, FORMAT, role, scene_hash, step, len(payload), payload_checksum(payload))
    tmp = path + ".tmp"
    with open(tmp, "wb") as f:
        f.write(header + payload)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def resume_step(folder):
    """The step a complete checkpoint directory holds (its manifest's)."""
    with open(os.path.join(folder, "manifest.json"), encoding="utf-8") as f:
        return int(json.load(f)["step"])


def read(folder, role, scene_hash, step):
    """This role's payload from checkpoint directory `folder`, its header checked."""
    path = os.path.join(folder, f"{ROLE_NAMES[role]}.bin")
    with open(path, "rb") as f:
        data = f.read()
    if len(data) < HEADER.size:
        raise Halt(f"{path}: not a grains checkpoint")
    magic, fmt, code, hash_, at, length, checksum = HEADER.unpack_from(data)
    payload = data[HEADER.size :]
    problems = [
        (magic != MAGIC, "not a grains checkpoint"),
        (fmt != FORMAT, f"checkpoint format {fmt}, this participant reads {FORMAT}"),
        (code != role, f"written by role code {code}"),
        (hash_ != scene_hash, f"written for scene hash {hash_:016x}, this run's is {scene_hash:016x}"),
        (at != step, f"holds step {at}, the manifest says {step}"),
        (len(payload) != length or payload_checksum(payload) != checksum, "damaged (length or checksum)"),
    ]
    for bad, why in problems:
        if bad:
            raise Halt(f"{path}: {why}")
    return payload
