"""Drives the live viewer in headless Chromium over the DevTools protocol (stdlib only).

    python3 tests/python/viewer_check.py URL STEP SHOT.png [click BUTTON_ID WAIT_TEXT]

Opens URL (the page `grains run --bridge --view` prints), waits in real time until the page
shows a summary of macro-step STEP (`any`: of any step) and has drawn a view, saves a screenshot to SHOT.png, and
with `click` presses the button and waits until the command's line in #acks contains
WAIT_TEXT. Prints one JSON object: status, the summary text (at the end, and at the
screenshot), data-step, drawn, the views' steps, the acks text. Exits 1 on a timeout (20 s each wait), after printing what it saw.

Chromium runs with --remote-debugging-pipe: it reads commands on fd 3 and writes replies on
fd 4, each a JSON text ended by a NUL byte.
"""

import base64
import json
import os
import subprocess
import sys
import time

url, step, shot = sys.argv[1], sys.argv[2], sys.argv[3]
click = sys.argv[4:7] if len(sys.argv) > 4 and sys.argv[4] == "click" else None

c_in_r, c_in_w = os.pipe()
c_out_r, c_out_w = os.pipe()


def child_fds():
    # Through fresh numbers first, so that neither dup2 overwrites the other's source.
    a, b = os.dup(c_in_r), os.dup(c_out_w)
    os.dup2(a, 3)
    os.dup2(b, 4)


chrome = subprocess.Popen(
    ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--remote-debugging-pipe",
     "--window-size=1280,720", "about:blank"],
    close_fds=False, preexec_fn=child_fds,
    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
os.close(c_in_r)
os.close(c_out_w)
to_chrome = os.fdopen(c_in_w, "wb", buffering=0)
from_chrome = os.fdopen(c_out_r, "rb", buffering=0)
buf = b""
next_id = 0


def call(method, params=None, session=None):
    """Sends one command, returns its result (events in between are skipped)."""
    global buf, next_id
    next_id += 1
    msg = {"id": next_id, "method": method, "params": params or {}}
    if session:
        msg["sessionId"] = session
    to_chrome.write(json.dumps(msg).encode() + b"\0")
    while True:
        while b"\0" not in buf:
            chunk = from_chrome.read(65536)
            if not chunk:
                raise SystemExit("chromium closed the pipe")
            buf += chunk
        text, buf = buf.split(b"\0", 1)
        reply = json.loads(text)
        if reply.get("id") == next_id:
            if "error" in reply:
                raise SystemExit(f"{method}: {reply['error']}")
            return reply["result"]


REPORT = """({
  status: document.getElementById('status').textContent,
  summary: document.getElementById('summary').textContent,
  step: document.documentElement.dataset.step,
  drawn: window.grainsViewer ? window.grainsViewer.drawn : 0,
  views: window.grainsViewer ? Object.fromEntries(Object.entries(window.grainsViewer.lastViews || {})
           .filter(([k, v]) => v).map(([k, v]) => [k, v.step])) : {},
  acks: document.getElementById('acks').textContent,
  fps: document.getElementById('fps').textContent,
  pressure: window.grainsViewer ? Object.fromEntries(Object.entries(window.grainsViewer.lastViews || {})
           .filter(([k, v]) => v).map(([k, v]) => [k, v.pressure])) : {},
})"""

at_shot = None
try:
    target = call("Target.createTarget", {"url": url})["targetId"]
    session = call("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]

    def evaluate(expr):
        r = call("Runtime.evaluate", {"expression": expr, "returnByValue": True}, session)
        return r.get("result", {}).get("value")

    def wait(cond):
        deadline = time.time() + 20
        while time.time() < deadline:
            if evaluate(f"(() => {{ try {{ return !!({cond}); }} catch (e) {{ return false; }} }})()"):
                return True
            time.sleep(0.2)
        return False

    shown = "document.documentElement.dataset.step !== undefined" if step == "any" else f"document.documentElement.dataset.step === '{step}'"
    ok = wait(f"{shown} && window.grainsViewer.drawn > 0")
    if ok:
        # The frame after the last draw is on screen.
        time.sleep(0.3)
        png = call("Page.captureScreenshot", {"format": "png"}, session)["data"]
        at_shot = evaluate("document.getElementById('summary').textContent")
        with open(shot, "wb") as f:
            f.write(base64.b64decode(png))
    if ok and click:
        button, text = click[1], click[2]
        evaluate(f"document.getElementById({json.dumps(button)}).click()")
        ok = wait(f"document.getElementById('acks').textContent.includes({json.dumps(text)})")
    report = evaluate(REPORT)
    report["summary_at_shot"] = at_shot if ok else None
    print(json.dumps(report, indent=1))
    sys.exit(0 if ok else 1)
finally:
    chrome.kill()
    chrome.wait()
