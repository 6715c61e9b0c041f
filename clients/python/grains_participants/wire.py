"""The messages of the grains protocol, its checksum and its scene hash.

Implements protocol/README.md §3 (message layouts: `StepHeader`, `Hello`, `Welcome`,
`StepBegin`, `RasterNode`, `NodeVelocity`, `Summary`, `Control`, `Ack`, `ViewPoint`,
`ZoneCell`) and §4 (payload checksum, scene hash).

Each message is a `ctypes.Structure` with the fields of its table in §3, in order; the
iceoryx2 bindings read its size and alignment from ctypes and its type name from the static
`type_name()` (§1: `grains.<Name>.v1`, or `grains.Hello` / `grains.Welcome`). For bulk reads
and writes in place the same layouts are also given as numpy dtypes (`RASTER_NODE`,
`NODE_VELOCITY`, `ZONE_CELL`, `VIEW_POINT`).
"""

import ctypes

import numpy as np

PROTOCOL_VERSION = 1
#: `Hello.magic` / `Welcome.magic`: ASCII "GRAINS\0\0" read little-endian (§3.2).
HELLO_MAGIC = 0x0000_534E_4941_5247

# Role codes (§2).
LAUNCHER, DEM, MPM, COUPLER, ORACLE, BRIDGE = 1, 2, 3, 4, 5, 6

# Hello.flags (§3.2) and Welcome.verdict (§3.3).
HELLO_ADMISSION, HELLO_READY = 0, 1
VERDICT_ACCEPTED, VERDICT_START = 0, 100
VERDICTS = {
    1: "wrong protocol version",
    2: "wrong scene (pass the run's copy of the scene file, unchanged)",
    3: "the run has no such role",
    4: "the role is already taken",
}

# StepBegin.flags (§3.4).
STEP_STOP, STEP_CHECKPOINT = 1, 2

# ZoneCell.zone (§3.9).
ZONE_CONTINUUM, ZONE_HYBRID, ZONE_DISCRETE = 0, 1, 2

# Control.command (§3.8) and Ack.status.
PAUSE, RESUME, STOP, SNAPSHOT, SET, CHECKPOINT = 1, 2, 3, 4, 5, 6
ACK_APPLIED, ACK_UNKNOWN_COMMAND, ACK_UNSUPPORTED, ACK_BUSY = 0, 1, 2, 3

u8, u32, u64, f64 = ctypes.c_uint8, ctypes.c_uint32, ctypes.c_uint64, ctypes.c_double


def _named(name):
    """Class decorator: the iceoryx2 type name of a message (§1)."""

    def attach(cls):
        cls.type_name = staticmethod(lambda: name)
        return cls

    return attach


@_named("grains.StepHeader.v1")
class StepHeader(ctypes.Structure):
    """§3.1: user header of every data service (80 bytes)."""

    _fields_ = [
        ("protocol_version", u32),
        ("sender", u32),
        ("step", u64),
        ("time", f64),
        ("dt", f64),
        ("checksum", u64),
        ("flags", u64),
        ("run_id", u8 * 32),
    ]


@_named("grains.Hello")
class Hello(ctypes.Structure):
    """§3.2: participant -> launcher (64 bytes)."""

    _fields_ = [
        ("magic", u64),
        ("scene_hash", u64),
        ("protocol_version", u32),
        ("role", u32),
        ("pid", u32),
        ("flags", u32),
        ("run_id", u8 * 32),
    ]


@_named("grains.Welcome")
class Welcome(ctypes.Structure):
    """§3.3: launcher -> participants (64 bytes)."""

    _fields_ = [
        ("magic", u64),
        ("scene_hash", u64),
        ("protocol_version", u32),
        ("role", u32),
        ("pid", u32),
        ("verdict", u32),
        ("run_id", u8 * 32),
    ]


@_named("grains.StepBegin.v1")
class StepBegin(ctypes.Structure):
    """§3.4: coupler -> dem, mpm, oracle (8 bytes, alignment 4)."""

    _fields_ = [("flags", u32), ("substeps", u32)]


@_named("grains.RasterNode.v1")
class RasterNode(ctypes.Structure):
    """§3.5: DEM or MPM -> coupler, one grid node (40 bytes)."""

    _fields_ = [("node", u64), ("mass", f64), ("momentum", f64 * 3)]


@_named("grains.NodeVelocity.v1")
class NodeVelocity(ctypes.Structure):
    """§3.6: coupler -> DEM and MPM, one constrained node velocity (32 bytes)."""

    _fields_ = [("node", u64), ("velocity", f64 * 3)]


@_named("grains.Summary.v1")
class Summary(ctypes.Structure):
    """§3.7: every participant -> launcher, one per step (104 bytes)."""

    _fields_ = [
        ("role", u32),
        ("status", u32),
        ("step", u64),
        ("time", f64),
        ("n_items", u64),
        ("n_nodes", u64),
        ("mass", f64),
        ("momentum", f64 * 3),
        ("kinetic_energy", f64),
        ("checksum", u64),
        ("compute_ns", u64),
        ("wait_ns", u64),
    ]


@_named("grains.Control.v1")
class Control(ctypes.Structure):
    """§3.8: launcher or bridge -> time owner; coupler -> solvers (24 bytes)."""

    _fields_ = [("seq", u64), ("command", u32), ("key", u32), ("value", f64)]


@_named("grains.Ack.v1")
class Ack(ctypes.Structure):
    """§3.8: time owner -> launcher and bridge (32 bytes)."""

    _fields_ = [
        ("seq", u64),
        ("step", u64),
        ("command", u32),
        ("status", u32),
        ("key", u32),
        ("_pad", u32),
    ]


@_named("grains.ViewPoint.v2")
class ViewPoint(ctypes.Structure):
    """§3.8a: DEM or MPM -> bridge, one item of a decimated view (72 bytes)."""

    _fields_ = [("id", u64), ("position", f64 * 3), ("velocity", f64 * 3), ("size", f64), ("pressure", f64)]


@_named("grains.ZoneCell.v1")
class ZoneCell(ctypes.Structure):
    """§3.9: oracle -> DEM and MPM, the zone of one grid cell (24 bytes)."""

    _fields_ = [("cell", u64), ("zone", u32), ("_pad", u32), ("distance", f64)]


# The same layouts as numpy dtypes, for reading and writing slices in place.
RASTER_NODE = np.dtype([("node", "<u8"), ("mass", "<f8"), ("momentum", "<f8", (3,))])
NODE_VELOCITY = np.dtype([("node", "<u8"), ("velocity", "<f8", (3,))])
ZONE_CELL = np.dtype([("cell", "<u8"), ("zone", "<u4"), ("_pad", "<u4"), ("distance", "<f8")])
VIEW_POINT = np.dtype(
    [("id", "<u8"), ("position", "<f8", (3,)), ("velocity", "<f8", (3,)), ("size", "<f8"), ("pressure", "<f8")]
)
assert RASTER_NODE.itemsize == ctypes.sizeof(RasterNode) == 40
assert NODE_VELOCITY.itemsize == ctypes.sizeof(NodeVelocity) == 32
assert ZONE_CELL.itemsize == ctypes.sizeof(ZoneCell) == 24
assert VIEW_POINT.itemsize == ctypes.sizeof(ViewPoint) == 72
assert ctypes.sizeof(StepHeader) == 80 and ctypes.sizeof(Summary) == 104
assert ctypes.sizeof(Hello) == ctypes.sizeof(Welcome) == 64
assert ctypes.sizeof(StepBegin) == 8 and ctypes.alignment(StepBegin) == 4


def run_id_bytes(run_id):
    """The run id as it travels: ASCII, zero-padded to 32 bytes (§3)."""
    raw = run_id.encode("ascii")[:32]
    return (u8 * 32)(*raw)


def view(address, count, dtype):
    """A numpy array of `count` elements of `dtype` over the memory at `address` (no copy)."""
    buffer = (ctypes.c_ubyte * (count * dtype.itemsize)).from_address(address)
    return np.frombuffer(buffer, dtype=dtype)


# ---------------------------------------------------------------------------------------
# §4 Checksums and hashes

_MASK = (1 << 64) - 1
_P = 0x0000_0100_0000_01B3
_LANES = (0xCBF29CE484222325, 0x9E3779B97F4A7C15, 0xC2B2AE3D27D4EB4F, 0x165667B19E3779F9)


def checksum(address, n_bytes):
    """§4 payload checksum of the `n_bytes` (a multiple of 8) at `address`."""
    words = view(address, n_bytes // 8, np.dtype("<u8")).tolist()
    lane = list(_LANES)
    for i, w in enumerate(words):
        lane[i & 3] = ((lane[i & 3] ^ w) * _P) & _MASK
    h = _LANES[0]
    for k in range(4):
        h = ((h ^ lane[k]) * _P) & _MASK
    h = ((h ^ (8 * len(words))) * _P) & _MASK
    return h if h != 0 else 1  # 0 on the wire means "not computed"


def scene_hash(data):
    """§4 scene hash: 64-bit FNV-1a of the scene file's bytes."""
    h = 0xCBF29CE484222325
    for b in data:
        h = ((h ^ b) * 0x100000001B3) & _MASK
    return h
