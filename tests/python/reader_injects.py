"""A reader tries to publish a fake summary to the other clients of a bridge with access
control; a second client (a steerer) listens to the summaries.

    python3 tests/python/reader_injects.py tcp/127.0.0.1:7447 <run-id> viewer:look pilot:fly

Prints "received N summaries, F fake" and exits 0 when the listener received real summaries
and no fake one, 1 otherwise.
"""

import json
import sys
import time

import zenoh


def session(endpoint, credentials):
    user, password = credentials.split(":", 1)
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/auth/usrpwd/user", json.dumps(user))
    conf.insert_json5("transport/auth/usrpwd/password", json.dumps(password))
    return zenoh.open(conf)


endpoint, run, reader, listener = sys.argv[1:5]
key = f"grains/{run}/state/summary"
with session(endpoint, listener) as ears, session(endpoint, reader) as mouth:
    got = []
    sub = ears.declare_subscriber(key, lambda s: got.append(s.payload.to_string()))
    time.sleep(0.5)
    for _ in range(20):
        mouth.put(key, "FAKE")
        time.sleep(0.05)
    time.sleep(1.0)
    fake = sum(1 for g in got if g == "FAKE")
    print(f"received {len(got)} summaries, {fake} fake")
    sys.exit(0 if got and fake == 0 else 1)
