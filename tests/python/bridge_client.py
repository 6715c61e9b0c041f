"""A remote client of a grains run in Python: a user of the `grains_client` package
(clients/python), which the test venv installs.

    python3 tests/python/bridge_client.py tcp/127.0.0.1:7447 <run-id>

Lists the runs, receives the run's summaries, queries the latest state and the grains' view
(as NumPy arrays), has a bad command refused (an exception), pauses the run (and checks that
the step counter stops), resumes it (and checks that it moves again) and stops it (each an
acknowledgement). Prints what it saw; exits 0 when every check held, 1 when one failed, 3
when the package is not installed.
"""

import json
import sys
import time
import numpy as np

try:
    from grains_client import Client, Refused
except ImportError as e:
    print(f"bridge_client: {e}: pip install ./clients/python", file=sys.stderr)
    sys.exit(3)


def fail(why):
    print(f"bridge_client: FAILED: {why}", file=sys.stderr)
    sys.exit(1)


def main():
    endpoint, run = sys.argv[1], sys.argv[2]
    with Client(endpoint) as grains:
        if run not in grains.runs():
            fail(f"run {run} is not listed: {grains.runs()}")

        # Live summaries: three of them, steps increasing.
        steps = [s["step"] for s in grains.summaries(run, count=3, timeout=30.0)]
        if len(steps) < 3:
            fail(f"received {len(steps)} summaries in 30 s")
        if steps != sorted(steps) or steps[0] == steps[-1]:
            fail(f"summary steps do not advance: {steps}")
        print(f"summaries: steps {steps}")

        state = grains.latest(run)
        for key in ("step", "time", "grains", "kinetic_energy", "momentum", "participants", "steps_per_s"):
            if key not in state:
                fail(f"the state has no {key!r}: {state}")
        print(f"latest: step {state['step']}, {state['grains']} grains, KE {state['kinetic_energy']:.3e} J")

        # The latest view of the grains: all of them here (fewer than 5,000), 3D positions,
        # taken once some grains have reached the floor (a loaded machine runs the fall slower
        # than the summaries above take).
        deadline = time.monotonic() + 60.0
        view = grains.view(run, "dem")
        while not (view.positions[:, 1] < view.sizes - 1e-9).any() and time.monotonic() < deadline:
            time.sleep(0.2)
            view = grains.view(run, "dem")
        n = state["grains"]
        if not (view.total == n and view.ids.shape == (n,) and view.positions.shape == (n, 3) and view.sizes.shape == (n,)):
            fail(f"view of {len(view.ids)} of {view.total} grains, positions {view.positions.shape}; the run has {n}")
        if not (view.sizes > 0).all() or not (view.speeds() >= 0).all():
            fail("a view size is not positive")
        # A grain's pressure is its contacts' mean stress: finite, never tensile without
        # cohesion, and positive for every grain pressed into the floor (y = 0) of the box the
        # grains settle in (the rest may still be falling).
        p = view.pressures
        if not (p.shape == (n,) and np.isfinite(p).all() and (p >= -1e-9 * p.max()).all()):
            fail(f"the grains' view pressures should be finite and not negative: {p[:5]}")
        on_floor = view.positions[:, 1] < view.sizes - 1e-9  # pressed in by more than the views' f32 rounding
        if not (on_floor.any() and (p[on_floor] > 0).all()):
            fail(f"{on_floor.sum()} grains press into the floor, {(p[on_floor] > 0).sum()} of them with a pressure")
        print(f"view: {len(view.ids)} grains at step {view.step}, fastest {view.speeds().max():.3e} m/s")

        # A refusal is an exception, with the reason, and changes nothing.
        try:
            grains.set(run, "gravity.z", 1.0)
            fail("set gravity.z in a 2D run was not refused")
        except Refused as why:
            print(f"refused: {why}")

        paused_at = grains.pause(run).step
        time.sleep(0.5)
        first = grains.latest(run)
        time.sleep(1.0)
        second = grains.latest(run)
        if not (first["step"] == second["step"] == paused_at and second["paused"]):
            fail(f"paused at step {paused_at}, but the state went {first['step']} -> {second['step']} (paused: {second['paused']})")
        print(f"paused at step {paused_at}: the step stayed at {second['step']} for 1 s")

        ack = grains.resume(run)
        time.sleep(1.0)
        moving = grains.latest(run)
        if moving["step"] <= paused_at or moving["paused"]:
            fail(f"resumed after step {ack.step}, but the state is at step {moving['step']} (paused: {moving['paused']})")
        print(f"resumed after step {ack.step}: now at step {moving['step']}")

        ack = grains.stop(run)
        print(f"stopped after step {ack.step}")
        print(json.dumps({"stopped_at": ack.step, "paused_at": paused_at}))


if __name__ == "__main__":
    main()
