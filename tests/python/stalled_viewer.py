"""A remote viewer that subscribes to a run's views and never reads them: its callback blocks
on the first sample for good, so zenoh stops taking data off its socket.

    python3 tests/python/stalled_viewer.py tcp/127.0.0.1:7447 <run-id>

Prints "subscribed" once the subscription is declared, then waits until killed.
"""

import json
import sys
import threading

import zenoh

endpoint, run = sys.argv[1], sys.argv[2]
conf = zenoh.Config()
conf.insert_json5("mode", '"client"')
conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
conf.insert_json5("scouting/multicast/enabled", "false")
never = threading.Event()
with zenoh.open(conf) as session:
    sub = session.declare_subscriber(f"grains/{run}/state/view/*", lambda sample: never.wait())
    print("subscribed", flush=True)
    never.wait()
