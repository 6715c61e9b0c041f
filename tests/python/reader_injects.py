"""A reader tries to publish a fake summary to the other clients of a bridge with access
control, and to pause the run; a second client (a steerer) listens to the summaries. Both
are `grains_client.Client`s with user and password.

    python3 tests/python/reader_injects.py tcp/127.0.0.1:7447 <run-id> viewer:look pilot:fly

Prints "received N summaries, F fake" and exits 0 when the listener received real summaries
and no fake one and the reader's pause got no answer (zenoh drops it), 1 otherwise.
"""

import sys
import time

from grains_client import Client, NoAnswer

endpoint, run, reader, listener = sys.argv[1:5]
key = f"grains/{run}/state/summary"
with Client(endpoint, *listener.split(":", 1)) as ears, Client(endpoint, *reader.split(":", 1)) as mouth:
    got = []
    sub = ears.session.declare_subscriber(key, lambda s: got.append(s.payload.to_string()))
    time.sleep(0.5)
    for _ in range(20):
        mouth.session.put(key, "FAKE")
        time.sleep(0.05)
    time.sleep(1.0)
    fake = sum(1 for g in got if g == "FAKE")
    print(f"received {len(got)} summaries, {fake} fake")
    try:
        mouth.steer(run, {"command": "pause"}, timeout=2.0)
        print("the reader's pause was answered")
        sys.exit(1)
    except NoAnswer:
        print("the reader's pause got no answer")
    sys.exit(0 if got and fake == 0 else 1)
