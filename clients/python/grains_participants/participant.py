"""Joining a grains run and talking within it, for any participant.

- `Participant.__init__`: protocol/README.md §1 (the run's iceoryx2 domain, dead-node cleanup
  off, the node name).
- `Participant.publisher` / `Participant.subscriber`: §1 (each publish-subscribe service
  opened with exactly the settings of the table, paired with an event service of the same
  name; sends bounded to 5 s).
- `Participant.join` / `Participant.wait_until` / `Participant.ready`: §5 (the handshake).
- `Participant.check_alive` / `Participant.watch_peers` / `Participant.receive`: §7 (stop
  requests, dead peers, 100 ms waits).
- `Participant.header` / `Participant.check_message`: §3.1 and §7 (headers written whole,
  received headers checked).
"""

import argparse
import ctypes
import faulthandler
import os
import signal
import sys
import time

import iceoryx2 as iox2

from . import wire

#: One blocking wait on a listener (§7).
POLL = 0.1
#: Dead peers are looked for every this many empty waits, or this often (§7).
DEAD_CHECK_EVERY = 3
DEAD_CHECK_PERIOD = 0.3
#: A send blocked by a full subscriber buffer gives up after this long (§1).
STALLED_SUBSCRIBER = 5.0

#: §1: (max publishers, max subscribers, subscriber buffer, overflow) of every service this
#: package opens.
SERVICES = {
    "grains/run/hello": (8, 1, 8, False),
    "grains/run/welcome": (1, 8, 8, False),
    "grains/run/control": (2, 1, 16, False),
    "grains/run/ack": (1, 2, 16, False),
    "grains/step/command": (1, 3, 16, False),
    "grains/run/summary": (6, 2, 64, False),
    "grains/step/begin": (1, 3, 2, False),
    "grains/dem/raster": (1, 1, 2, False),
    "grains/mpm/raster": (1, 1, 2, False),
    "grains/coupler/velocities": (1, 2, 2, False),
    "grains/oracle/zones": (1, 2, 2, False),
    "grains/dem/view": (1, 1, 1, True),
    "grains/mpm/view": (1, 1, 1, True),
}

NODE_NAMES = {
    wire.LAUNCHER: "grains",
    wire.DEM: "grains-dem",
    wire.MPM: "grains-mpm",
    wire.COUPLER: "grains-coupler",
    wire.ORACLE: "grains-oracle",
    wire.BRIDGE: "grains-bridge",
}


class Halt(Exception):
    """Why a participant stops early; `code` is its exit code (§7)."""

    code = 1


class Interrupted(Halt):
    code = 130


class Refused(Halt):
    code = 2


class PeerDied(Halt):
    code = 1


_signalled = False


def _on_signal(signum, frame):
    global _signalled
    _signalled = True


class Publisher:
    """A publisher of one service and the notifier of its event service (§1)."""

    def __init__(self, node, name, element, header, initial_len):
        self.name = name
        self.service = _pubsub(node, name, element, header)
        self.event = node.service_builder(iox2.ServiceName.new(name)).event().open_or_create()
        overflow = SERVICES[name][3]
        self.port = (
            self.service.publisher_builder()
            .initial_max_slice_len(max(initial_len, 1))
            .allocation_strategy(iox2.AllocationStrategy.PowerOfTwo)
            .max_loaned_samples(1)
            .backpressure_strategy(
                iox2.BackpressureStrategy.DiscardData
                if overflow
                else iox2.BackpressureStrategy.RetryUntilDelivered
            )
            .create()
        )
        self.notifier = self.event.notifier_builder().create()
        self.header_type = header
        self.element = element

    def publish(self, n, fill):
        """Loans a slice of `n` elements, lets `fill(header, address)` write the header (a
        ctypes struct, or None without a user header) and the payload in place, sends, notifies.
        """
        sample = self.port.loan_slice_uninit(n)
        header = sample.user_header().contents if self.header_type is not None else None
        fill(header, sample.payload_ptr)
        sample = sample.assume_init()
        # The Python bindings of iceoryx2 0.10 have no backpressure handler: a watchdog
        # thread ends the process (exit 1) if the send is still blocked after 5 s (§1, §7).
        faulthandler.dump_traceback_later(STALLED_SUBSCRIBER, exit=True)
        try:
            sample.send()
        finally:
            faulthandler.cancel_dump_traceback_later()
        self.notifier.notify()

    def subscriber_count(self):
        self.port.update_connections()
        return self.service.dynamic_config.number_of_subscribers

    def close(self):
        self.notifier.delete()
        self.port.delete()
        self.service = self.event = None


class Subscriber:
    """A subscriber of one service and its listener on the event service (§1)."""

    def __init__(self, node, name, element, header):
        self.name = name
        self.service = _pubsub(node, name, element, header)
        self.event = node.service_builder(iox2.ServiceName.new(name)).event().open_or_create()
        # The listener first: a notification reaches only listeners that exist (§1).
        self.listener = self.event.listener_builder().create()
        self.port = self.service.subscriber_builder().create()

    def receive(self, timeout):
        """The next sample, or None after `timeout` seconds (or a signal) without one."""
        deadline = time.monotonic() + timeout
        while True:
            sample = self.port.receive()
            if sample is not None:
                return sample
            now = time.monotonic()
            if now >= deadline:
                return None
            try:
                # Events are sticky: one sent since `receive` above still wakes us.
                self.listener.timed_wait(iox2.Duration.from_secs_f64(deadline - now))
            except iox2.ListenerWaitError as e:
                if str(e) == "InterruptSignal":
                    return None  # a signal counts as an empty wait (§7)
                raise

    def publisher_count(self):
        # (The Python Subscriber has no update_connections; the count is the service's.)
        return self.service.dynamic_config.number_of_publishers

    def close(self):
        self.port.delete()
        self.listener.delete()
        self.service = self.event = None


def _pubsub(node, name, element, header):
    """Opens publish-subscribe service `name` with exactly the settings of §1."""
    max_pub, max_sub, buffer, overflow = SERVICES[name]
    builder = node.service_builder(iox2.ServiceName.new(name)).publish_subscribe(
        iox2.Slice[element]
    )
    if header is not None:
        builder = builder.user_header(header)
    return (
        builder.max_publishers(max_pub)
        .max_subscribers(max_sub)
        .subscriber_max_buffer_size(buffer)
        .subscriber_max_borrowed_samples(1)
        .history_size(0)
        .enable_safe_overflow(overflow)
        .open_or_create()
    )


class Participant:
    """One participant's membership of a run."""

    def __init__(self, role, run_id, scene_hash, connect_timeout):
        self.role = role
        self.run_id = run_id
        self.run_id_bytes = bytes(wire.run_id_bytes(run_id))
        self.scene_hash = scene_hash
        #: Seconds each start-up wait may last; None: no limit (§7).
        self.connect_timeout = connect_timeout if connect_timeout > 0 else None
        self.ports = []
        #: The run's output directory (--out-dir) and, resumed, the checkpoint directory and
        #: its step (--resume, §6.4); set by `main`.
        self.out_dir = None
        self.resume_dir = None
        self.resume_step = 0
        self._empty_waits = 0
        self._last_dead_check = time.monotonic()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, _on_signal)

        # §1: iceoryx2 quiet unless IOX2_LOG_LEVEL says otherwise; the run's domain; no
        # node removes a dead one as it comes or goes.
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        self.config = iox2.config.global_config()
        self.config.global_cfg.prefix = iox2.FileName.new(f"grains_{run_id}_")
        self.config.global_cfg.node.cleanup_dead_nodes_on_creation = False
        self.config.global_cfg.node.cleanup_dead_nodes_on_destruction = False
        self.node = (
            iox2.NodeBuilder.new()
            .name(iox2.NodeName.new(NODE_NAMES[role]))
            .config(self.config)
            # This process handles SIGINT/SIGTERM itself (a flag checked at every wait).
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc)
        )

    # -- ports ---------------------------------------------------------------------------

    def publisher(self, name, element, header=wire.StepHeader, initial_len=1):
        port = Publisher(self.node, name, element, header, initial_len)
        self.ports.append(port)
        return port

    def subscriber(self, name, element, header=wire.StepHeader):
        port = Subscriber(self.node, name, element, header)
        self.ports.append(port)
        return port

    def close(self):
        """Closes every port, the last opened first, then the node: a clean exit leaves no
        dead node behind (§7). Call it before the process ends; do not rely on the garbage
        collector at interpreter exit."""
        while self.ports:
            self.ports.pop().close()
        self.node = None

    # -- §5 the handshake ----------------------------------------------------------------

    def join(self):
        """Asks the launcher for admission; returns once accepted (raises Refused else)."""
        self.hello = self.publisher("grains/run/hello", wire.Hello, header=None)
        self.welcome = self.subscriber("grains/run/welcome", wire.Welcome, header=None)
        self.wait_until(
            f"the launcher of run {self.run_id}",
            lambda: self.welcome.publisher_count() >= 1 and self.hello.subscriber_count() >= 1,
        )
        self._say_hello(wire.HELLO_ADMISSION)
        verdict = self._wait_welcome(start=False)
        if verdict.verdict != wire.VERDICT_ACCEPTED:
            why = wire.VERDICTS.get(verdict.verdict, f"verdict code {verdict.verdict}")
            raise Refused(
                f"the run refused this {NODE_NAMES[self.role]}: {why} (the run speaks protocol "
                f"version {verdict.protocol_version}, scene hash {verdict.scene_hash:#018x}; "
                f"this participant version {wire.PROTOCOL_VERSION}, scene hash {self.scene_hash:#018x})"
            )

    def ready(self):
        """Says "ready" (every port connected) and waits for the start broadcast."""
        self._say_hello(wire.HELLO_READY)
        self._wait_welcome(start=True)

    def _say_hello(self, flags):
        def fill(_header, address):
            hello = wire.Hello.from_address(address)
            hello.magic = wire.HELLO_MAGIC
            hello.scene_hash = self.scene_hash
            hello.protocol_version = wire.PROTOCOL_VERSION
            hello.role = self.role
            hello.pid = os.getpid()
            hello.flags = flags
            hello.run_id[:] = self.run_id_bytes

        self.hello.publish(1, fill)

    def _wait_welcome(self, start):
        """The welcome addressed to this participant, or (start) the start broadcast; every
        other welcome is skipped (§3.3)."""
        what = "the start of the run" if start else "admission by the launcher"
        deadline = None if self.connect_timeout is None else time.monotonic() + self.connect_timeout
        while True:
            sample = self.welcome.receive(POLL)
            if sample is not None:
                w = None
                if sample.header.number_of_elements >= 1:
                    w = wire.Welcome.from_buffer_copy(ctypes.string_at(sample.payload_ptr, 64))
                sample.delete()
                if w is not None and w.magic == wire.HELLO_MAGIC:
                    mine = w.role == self.role and w.pid == os.getpid()
                    broadcast = w.role == 0 and w.verdict == wire.VERDICT_START
                    if (start and broadcast) or (not start and mine):
                        return w
                continue
            self.check_alive(what)
            if deadline is not None and time.monotonic() > deadline:
                raise Halt(f"no answer from the launcher: waited {self.connect_timeout:.0f} s for {what}")

    def wait_until(self, what, ready):
        """Polls `ready()` every 2 ms (start-up only) until it holds (§5)."""
        start = last_check = time.monotonic()
        while not ready():
            if _signalled:
                raise Interrupted("stopped by a signal")
            now = time.monotonic()
            if now - last_check >= DEAD_CHECK_PERIOD:
                last_check = now
                self.check_dead(what)
            if self.connect_timeout is not None and now - start > self.connect_timeout:
                raise Halt(f"{what} did not connect within {self.connect_timeout:.0f} s")
            time.sleep(0.002)

    # -- §7 liveness ---------------------------------------------------------------------

    def check_alive(self, waiting_for):
        """After every empty wait: a stop request at once, dead peers every third time."""
        if _signalled:
            raise Interrupted("stopped by a signal")
        self._empty_waits += 1
        if self._empty_waits % DEAD_CHECK_EVERY == 0:
            self.check_dead(waiting_for)

    def watch_peers(self):
        """Once per macro-step: a stop request, and dead peers if 300 ms have passed."""
        if _signalled:
            raise Interrupted("stopped by a signal")
        now = time.monotonic()
        if now - self._last_dead_check >= DEAD_CHECK_PERIOD:
            self._last_dead_check = now
            self.check_dead("its next step")

    def check_dead(self, waiting_for):
        """Lists the domain's nodes; any dead one but a bridge stops this participant. A dead
        bridge's stale resources are removed (its ports would stall our publishers)."""
        dead = []
        for state in iox2.Node.list(iox2.ServiceType.Ipc, self.config):
            if not isinstance(state, iox2.NodeState.Dead):
                continue
            view = state[0]
            details = view.details
            if details is None:
                dead.append("an unnamed participant")
                continue
            name = details.name.as_str()
            if name == "grains-bridge":
                view.try_remove_stale_resources()
                continue
            dead.append(f"{name} (pid {details.process_id})")
        if dead:
            raise PeerDied(
                f"{', '.join(dead)} died while {NODE_NAMES[self.role]} waited for {waiting_for}"
            )

    def receive(self, sub, what):
        """The next message of `sub`, waiting as long as the peers are alive (§7)."""
        while True:
            sample = sub.receive(POLL)
            if sample is not None:
                return sample
            self.check_alive(what)

    # -- §3.1 headers --------------------------------------------------------------------

    def header(self, h, step, time_, dt):
        """Writes a whole header of this participant into `h` (checksum and flags 0)."""
        h.protocol_version = wire.PROTOCOL_VERSION
        h.sender = self.role
        h.step = step
        h.time = time_
        h.dt = dt
        h.checksum = 0
        h.flags = 0
        h.run_id[:] = self.run_id_bytes

    def check_message(self, service, sample, step, itemsize):
        """§7: protocol version, run id, step and (when not 0) checksum of a message."""
        h = sample.user_header().contents
        if h.protocol_version != wire.PROTOCOL_VERSION:
            raise Halt(
                f"{service}: message speaks protocol version {h.protocol_version}, "
                f"this participant speaks {wire.PROTOCOL_VERSION}"
            )
        if bytes(h.run_id) != self.run_id_bytes:
            got = bytes(h.run_id).rstrip(b"\0").decode("ascii", "replace")
            raise Halt(f"{service}: message of run {got!r}, expected run {self.run_id!r}")
        if h.step != step:
            raise Halt(f"{service}: message of step {h.step}, expected step {step}")
        if h.checksum != 0:
            n = sample.header.number_of_elements
            actual = wire.checksum(sample.payload_ptr, n * itemsize)
            if actual != h.checksum:
                raise Halt(
                    f"{service}: step {step}: payload checksum {actual:#018x} does not match "
                    f"the header's {h.checksum:#018x} ({n} elements)"
                )


def main(role, name, what, prepare, make, argv=None):
    """§8: the arguments every participant binary takes; §7: exit 0 done, 1 failure, 2 bad
    input or refused, 130 stopped by a signal.

    `prepare(scene)` reads what the participant needs of the scene (an error there is bad
    input, exit 2); `make(participant, scene, prepared)` returns the object whose `run()`
    takes part in the run.
    """
    from .scene import Scene, SceneError

    parser = argparse.ArgumentParser(
        prog=f"python -m {name}",
        description=f"An external grains {what} (protocol/README.md). Start it with the arguments "
        f"`grains run <scene> --external {what.lower()}` prints.",
    )
    parser.add_argument("--scene", required=True, help="the run's copy of the scene file")
    parser.add_argument("--run-id", required=True, help="the run id the launcher printed")
    parser.add_argument("--out-dir", help="the run's output directory (checkpoints go under it, §6.4)")
    parser.add_argument("--resume", help="resume from this checkpoint directory (§6.4)")
    parser.add_argument(
        "--connect-timeout", type=float, default=60.0, help="seconds per start-up wait; 0: no limit"
    )
    args = parser.parse_args(argv)
    try:
        scene = Scene(args.scene)
        prepared = prepare(scene)
    except SceneError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return 2
    except (OSError, KeyError, ValueError, TypeError) as e:
        print(f"{name}: error: {args.scene}: {type(e).__name__}: {e}", file=sys.stderr)
        return 2
    participant = None
    try:
        participant = Participant(role, args.run_id, wire.scene_hash(scene.data), args.connect_timeout)
        participant.out_dir = args.out_dir
        if args.resume is not None:
            from . import checkpoint

            participant.resume_dir = args.resume
            participant.resume_step = checkpoint.resume_step(args.resume)
        make(participant, scene, prepared).run()
        return 0
    except Halt as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        return e.code
    except Exception as e:  # an iceoryx2 failure, a bug: exit 1 with the reason
        print(f"{name}: error: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    finally:
        if participant is not None:
            participant.close()

