"""A Python client of grains runs: watch and steer them through their zenoh bridge.

protocol/README.md §9 is what it speaks (zenoh 1.10, JSON payloads). A run opened with
`grains run <scene> --bridge [--steering]` answers it:

    from grains_client import Client, Refused

    with Client("tcp/127.0.0.1:7447") as grains:          # user=..., password=... with [auth]
        run = grains.runs()[0]                              # the runs whose bridge answers
        for summary in grains.summaries(run, count=3):      # live summaries (dicts)
            print(summary["step"], summary["kinetic_energy"])
        view = grains.view(run, "dem")                      # the grains as NumPy arrays
        print(view.positions.shape, view.speeds().max())
        ack = grains.pause(run)                             # an Ack: the step it took effect at
        try:
            grains.set(run, "gravity.z", 1.0)               # a 2D run has no z: refused
        except Refused as why:
            print(why)
        grains.resume(run)
        grains.stop(run)

Acknowledgements are return values (`Ack`), refusals are exceptions (`Refused`, with the
bridge's or the time owner's reason); a bridge that does not answer raises `NoAnswer`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from typing import Any, Iterator, Optional

import numpy as np
import zenoh

__all__ = ["Client", "Ack", "View", "Refused", "NoAnswer"]


class Refused(Exception):
    """The command was refused (steering off, a bad key or value, busy, not for this run):
    the reason is the message. Nothing changed."""


class NoAnswer(Exception):
    """No reply within the timeout: no bridge for this run at the endpoint, or a reader
    without steering rights (zenoh drops its command without a reply, §9)."""


@dataclass(frozen=True)
class Ack:
    """A command applied: `step` is the last macro-step completed when it took effect."""

    command: str
    step: int
    seq: int


@dataclass(frozen=True)
class View:
    """A solver's latest decimated view (at most 5,000 of its grains or points)."""

    run: str
    role: str
    step: int
    time: float
    #: How many the solver has (the view holds `len(ids)` of them, every k-th).
    total: int
    ids: np.ndarray
    #: (n, 3) [m]
    positions: np.ndarray
    #: (n, 3) [m/s]
    velocities: np.ndarray
    #: (n,) radius of a grain, half the spacing of a point [m]
    sizes: np.ndarray
    #: (n,) pressure [Pa, positive in compression]: a point's, or a grain's contacts' mean stress
    #: over its volume; NaN where the solver does not say
    pressures: np.ndarray

    def speeds(self) -> np.ndarray:
        """|v| of every item [m/s]."""
        return np.linalg.norm(self.velocities, axis=1)


class Client:
    """One zenoh session to a bridge endpoint (`tcp/HOST:PORT`), as a client; closed by
    `close()` or at the end of a `with` block."""

    def __init__(self, endpoint: str, user: Optional[str] = None, password: Optional[str] = None):
        conf = zenoh.Config()
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        if user is not None:
            conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
            conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password or ""))
        self.endpoint = endpoint
        self.session = zenoh.open(conf)

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self.session.close()

    # -- watching ----------------------------------------------------------------------

    def runs(self, timeout: float = 2.0) -> list[str]:
        """The ids of the runs whose bridge answers here (their liveliness tokens), sorted."""
        ids = set()
        for reply in self.session.liveliness().get("grains/*/alive/bridge", timeout=timeout):
            if reply.ok is not None:
                ids.add(str(reply.ok.key_expr).split("/")[1])
        return sorted(ids)

    def latest(self, run: str, timeout: float = 5.0) -> dict[str, Any]:
        """The run's latest summary (§9: step, time, counts, energy, momentum, `paused`,
        `steps_per_s`, `participants`)."""
        return self._query(f"grains/{run}/state/summary", timeout)

    def config(self, run: str, timeout: float = 5.0) -> dict[str, Any]:
        """The bridge's effective settings (no passwords)."""
        return self._query(f"grains/{run}/state/config", timeout)

    def summaries(self, run: str, count: Optional[int] = None, timeout: float = 30.0) -> Iterator[dict[str, Any]]:
        """Live summaries as they are published (at most the bridge's rate), `count` of them
        or until none came for `timeout` seconds."""
        sub = self.session.declare_subscriber(f"grains/{run}/state/summary")
        try:
            got, last = 0, time.monotonic()
            while count is None or got < count:
                sample = sub.try_recv()
                if sample is None:
                    if time.monotonic() - last > timeout:
                        return
                    time.sleep(0.005)
                    continue
                got, last = got + 1, time.monotonic()
                yield json.loads(sample.payload.to_string())
        finally:
            sub.undeclare()

    def view(self, run: str, role: str = "dem", timeout: float = 5.0) -> View:
        """The latest view of the grains (`dem`) or the points (`mpm`) as NumPy arrays."""
        if role not in ("dem", "mpm"):
            raise ValueError(f"role {role!r}: views are of 'dem' or 'mpm'")
        v = self._query(f"grains/{run}/state/view/{role}", timeout)
        return View(
            run=v["run"],
            role=v["role"],
            step=int(v["step"]),
            time=float(v["time"]),
            total=int(v["total"]),
            ids=np.asarray(v["id"], dtype=np.uint64),
            positions=np.asarray(v["position"], dtype=float).reshape(-1, 3),
            velocities=np.asarray(v["velocity"], dtype=float).reshape(-1, 3),
            sizes=np.asarray(v["size"], dtype=float),
            pressures=np.asarray([np.nan if p is None else p for p in v.get("pressure", [])], dtype=float),
        )

    # -- steering (the bridge must run with steering on, and the user be a steerer) ----

    def steer(self, run: str, command: dict[str, Any], timeout: float = 10.0) -> Ack:
        """Sends one command (§9's JSON); its `Ack`, or `Refused` with the reason."""
        for reply in self.session.get(f"grains/{run}/control", payload=json.dumps(command), timeout=timeout):
            if reply.ok is not None:
                a = json.loads(reply.ok.payload.to_string())
                return Ack(command=a["command"], step=int(a["step"]), seq=int(a["seq"]))
            why = reply.err.payload.to_string()
            try:
                why = json.loads(why).get("error", why)
            except (ValueError, AttributeError):
                pass
            raise Refused(f"{command.get('command')}: {why}")
        raise NoAnswer(f"{command.get('command')}: no answer from grains/{run}/control at {self.endpoint} in {timeout} s")

    def pause(self, run: str) -> Ack:
        return self.steer(run, {"command": "pause"})

    def resume(self, run: str) -> Ack:
        return self.steer(run, {"command": "resume"})

    def stop(self, run: str) -> Ack:
        return self.steer(run, {"command": "stop"})

    def snapshot(self, run: str) -> Ack:
        """A frame of every solver now (in the run's `frames/`)."""
        return self.steer(run, {"command": "snapshot"})

    def checkpoint(self, run: str) -> Ack:
        """A checkpoint after the next step (`grains resume` can go on from it)."""
        return self.steer(run, {"command": "checkpoint"})

    def set(self, run: str, key: str, value: float) -> Ack:
        """`gravity.x|y|z` [m/s²] or `wall.<k>.velocity.x|y|z` [m/s] from the Ack's step on."""
        return self.steer(run, {"command": "set", "key": key, "value": value})

    # -- helpers ---------------------------------------------------------------------

    def _query(self, key: str, timeout: float) -> dict[str, Any]:
        for reply in self.session.get(key, timeout=timeout):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_string())
            raise Refused(f"{key}: {reply.err.payload.to_string()}")
        raise NoAnswer(f"{key}: no answer at {self.endpoint} in {timeout} s")
