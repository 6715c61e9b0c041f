"""A remote client of a grains run in Python, with the eclipse-zenoh package from PyPI.

    python3 tests/python/bridge_client.py tcp/127.0.0.1:7447 <run-id>

Receives the run's summaries, queries the latest state, pauses the run (and checks that the
step counter stops), resumes it (and checks that it moves again) and stops it. Prints what it
saw; exits 0 when every check held, 1 when one failed, 3 when zenoh is not installed.
"""

import json
import sys
import time

try:
    import zenoh
except ImportError:
    print("bridge_client: the Python package eclipse-zenoh is missing: pip install eclipse-zenoh==1.10.2", file=sys.stderr)
    sys.exit(3)


def fail(why):
    print(f"bridge_client: FAILED: {why}", file=sys.stderr)
    sys.exit(1)


def latest(session, run):
    for reply in session.get(f"grains/{run}/state/summary", timeout=5.0):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_string())
    fail("no reply to the state query")


def command(session, run, body):
    for reply in session.get(f"grains/{run}/control", payload=json.dumps(body), timeout=10.0):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_string())
        fail(f"{body} refused: {reply.err.payload.to_string()}")
    fail(f"{body}: no answer")


def main():
    endpoint, run = sys.argv[1], sys.argv[2]
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    with zenoh.open(conf) as session:
        # Live summaries: three of them, steps increasing.
        sub = session.declare_subscriber(f"grains/{run}/state/summary")
        steps = []
        deadline = time.monotonic() + 30.0
        while len(steps) < 3 and time.monotonic() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.01)
                continue
            doc = json.loads(sample.payload.to_string())
            steps.append(doc["step"])
        if len(steps) < 3:
            fail(f"received {len(steps)} summaries in 30 s")
        if steps != sorted(steps) or steps[0] == steps[-1]:
            fail(f"summary steps do not advance: {steps}")
        print(f"summaries: steps {steps}")

        state = latest(session, run)
        for key in ("step", "time", "grains", "kinetic_energy", "momentum", "participants", "steps_per_s"):
            if key not in state:
                fail(f"the state has no {key!r}: {state}")
        print(f"latest: step {state['step']}, {state['grains']} grains, KE {state['kinetic_energy']:.3e} J")

        # The latest view of the grains: all of them here (fewer than 5,000), 3D positions.
        views = [json.loads(r.ok.payload.to_string()) for r in session.get(f"grains/{run}/state/view/dem", timeout=5.0) if r.ok is not None]
        if not views:
            fail("no view of the grains")
        view = views[0]
        if not (view["total"] == state["grains"] == view["count"] == len(view["id"]) == len(view["position"]) == len(view["size"])):
            fail(f"view of {view['count']} of {view['total']} grains, {len(view['position'])} positions; the run has {state['grains']}")
        if any(len(p) != 3 for p in view["position"]) or not all(s > 0 for s in view["size"]):
            fail("a view position is not 3D or a size is not positive")
        print(f"view: {view['count']} grains at step {view['step']}")

        ack = command(session, run, {"command": "pause"})
        paused_at = ack["step"]
        time.sleep(0.5)
        first = latest(session, run)
        time.sleep(1.0)
        second = latest(session, run)
        if not (first["step"] == second["step"] == paused_at and second["paused"]):
            fail(f"paused at step {paused_at}, but the state went {first['step']} -> {second['step']} (paused: {second['paused']})")
        print(f"paused at step {paused_at}: the step stayed at {second['step']} for 1 s")

        ack = command(session, run, {"command": "resume"})
        time.sleep(1.0)
        moving = latest(session, run)
        if moving["step"] <= paused_at or moving["paused"]:
            fail(f"resumed after step {ack['step']}, but the state is at step {moving['step']} (paused: {moving['paused']})")
        print(f"resumed after step {ack['step']}: now at step {moving['step']}")

        ack = command(session, run, {"command": "stop"})
        print(f"stopped after step {ack['step']}")
        print(json.dumps({"stopped_at": ack["step"], "paused_at": paused_at}))


if __name__ == "__main__":
    main()
