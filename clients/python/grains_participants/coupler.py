"""An external grains coupler in Python: the time owner of a coupled run.

It gives the same `metrics.csv` physics columns, byte for byte, as the built-in
`grains-coupler`. Attach it to a run that waits for an external coupler:

    grains run tests/scenes/hybrid_small_2d.toml --external coupler
    # the launcher prints: <path>/grains-coupler --scene <S> --run-id <R> --out-dir <D>
    python -m grains_participants.coupler --scene <S> --run-id <R> --out-dir <D>

What each part implements, in protocol/README.md:

- `main`: §8 (the arguments every participant binary takes) and §7 (exit codes);
- `Coupler.open_ports` / `Coupler.connected`: §5 (the coupler's ports and the peers it waits for);
- `Coupler.run`: §6.2 (the macro-step) and §6.3 (the end of a run);
- `Coupler.obey` / `accepts`: §3.8 (control commands, acknowledgements, forwarding);
- `Coupler.begin_step`, `Coupler.stop`: §3.4 (`StepBegin` and the STOP message);
- `Coupler.couple` / `constrain`: §3.5, §3.6 (rasters in, constrained velocities out) and
  the coupler's summary of §3.7;
- `checkpoint` (module): §6.4 (its empty checkpoint; a resumed run starts after it).
"""

import ctypes
import sys
import time

import numpy as np

from . import checkpoint, wire
from . import participant
from .participant import POLL, Halt

#: After acknowledging `stop`, the time owner keeps its ports this long (§3.8).
ACK_LINGER = 0.3
#: Commands forwarded in one check between two steps: the `step/command` buffer (§3.8).
FORWARD_AT_MOST = 16


def constrain(dem, mpm):
    """Constrains the nodes both rasters carry (§3.6) and totals them (§3.7).

    `dem` and `mpm` are numpy views (dtype `wire.RASTER_NODE`) of the two rasters, each
    sorted by strictly increasing node. Returns the shared nodes, their velocities (n x 3)
    and the summary fields (mass, momentum, kinetic energy).
    """
    nodes, i, j = np.intersect1d(dem["node"], mpm["node"], assume_unique=True, return_indices=True)
    # v = (p_dem + p_mpm) / (m_dem + m_mpm), in that order of operations; 0 where m <= 0.
    # numpy's element-wise + and / are single IEEE-754 operations, as the spec asks.
    m = dem["mass"][i] + mpm["mass"][j]
    p = dem["momentum"][i] + mpm["momentum"][j]
    v = np.zeros_like(p)
    np.divide(p, m[:, None], out=v, where=(m > 0)[:, None])

    # The totals: in node order, from +0.0, one IEEE-754 operation at a time. Plain Python
    # floats do exactly that; numpy's sum (pairwise) and Python >= 3.12's built-in sum()
    # (compensated) would round differently.
    mass = px = py = pz = ke = 0.0
    for mk, (vx, vy, vz) in zip(m.tolist(), v.tolist()):
        mass += mk
        px += mk * vx
        py += mk * vy
        pz += mk * vz
        ke += (0.5 * mk) * ((vx * vx + vy * vy) + vz * vz)
    return nodes, v, (mass, (px, py, pz), ke)


def first_unsorted(raster):
    """(position, node) of the first element whose node does not increase strictly, or None."""
    nodes = raster["node"]
    bad = np.flatnonzero(nodes[1:] <= nodes[:-1])
    if len(bad) == 0:
        return None
    at = int(bad[0]) + 1
    return at, int(raster["node"][at])


def accepts(scene, c):
    """Whether both solvers can carry out a `snapshot` or `set` command (§3.8)."""
    if c.command == wire.SNAPSHOT:
        return True
    if 1 <= c.key <= 3:  # gravity, axis key - 1
        axis, low, high, wall_ok = c.key - 1, -100.0, 100.0, True
    elif c.key >= 16 and (c.key - 16) % 4 < 3:  # velocity of wall (key - 16) // 4
        axis, low, high = (c.key - 16) % 4, -10.0, 10.0
        wall_ok = (c.key - 16) // 4 < scene.n_walls
    else:
        return False
    return low <= c.value <= high and wall_ok and axis < scene.dimension


class Coupler:
    """The coupler's ports and its loop."""

    def __init__(self, participant, scene):
        self.p = participant
        self.scene = scene
        self.paused = False
        #: A `checkpoint` command was applied: the next step begin carries STEP_CHECKPOINT.
        self.checkpoint_next = False

    def open_ports(self):
        """§5: every service of the coupler (in the order the built-in one opens them)."""
        p = self.p
        self.control = p.subscriber("grains/run/control", wire.Control)
        self.ack = p.publisher("grains/run/ack", wire.Ack)
        self.command = p.publisher("grains/step/command", wire.Control)
        self.dem_raster = p.subscriber("grains/dem/raster", wire.RasterNode)
        self.mpm_raster = p.subscriber("grains/mpm/raster", wire.RasterNode)
        self.begin = p.publisher("grains/step/begin", wire.StepBegin)
        self.velocities = p.publisher("grains/coupler/velocities", wire.NodeVelocity, initial_len=1024)
        self.summary = p.publisher("grains/run/summary", wire.Summary)

    def connected(self):
        """§5: the launcher, both solvers and every follower of the steps are connected."""
        followers = 3 if self.scene.has_oracle else 2
        return (
            self.control.publisher_count() >= 1
            and self.ack.subscriber_count() >= 1
            and self.dem_raster.publisher_count() >= 1
            and self.mpm_raster.publisher_count() >= 1
            and self.begin.subscriber_count() >= followers
            and self.command.subscriber_count() >= 2
            and self.velocities.subscriber_count() >= 2
            and self.summary.subscriber_count() >= 1
        )

    def run(self):
        """§5 then §6.2 for n = 1 .. steps, then §6.3."""
        p, scene = self.p, self.scene
        p.join()
        self.open_ports()
        p.wait_until("the DEM, the MPM, the oracle and the launcher", self.connected)
        p.ready()
        last = p.resume_step  # §6.4: a resumed run goes on after its checkpoint
        for step in range(last + 1, scene.steps + 1):
            p.watch_peers()
            if not self.obey(step):
                break
            start = (step - 1) * scene.dt  # a product, never a running sum (§6.1)
            asked, self.checkpoint_next = self.checkpoint_next, False
            self.begin_step(step, start, asked)
            wait_start = time.perf_counter_ns()
            report, compute_ns = self.couple(step, start)
            wait_ns = time.perf_counter_ns() - wait_start - compute_ns
            if checkpoint.due(scene, step, asked):
                # A coupler carries nothing from step to step: an empty payload (§6.4).
                checkpoint.write(p.out_dir, wire.COUPLER, p.scene_hash, step, b"")
            self.publish_summary(step, start, report, compute_ns, wait_ns)
            last = step
        self.stop(last)

    def obey(self, step):
        """§3.8: every command queued before `step`, acknowledged at step - 1; while paused,
        waits for more. Returns False when the run must stop."""
        done = step - 1
        forwarded = 0
        while True:
            sample = self.control.receive(POLL if self.paused else 0.0)
            if sample is None:
                if not self.paused:
                    return True
                self.p.check_alive("a resume command")
                continue
            c = None
            if sample.header.number_of_elements >= 1:
                c = wire.Control.from_buffer_copy(ctypes.string_at(sample.payload_ptr, 24))
            sample.delete()
            if c is None:
                continue
            if c.command in (wire.STOP, wire.PAUSE, wire.RESUME):
                status = wire.ACK_APPLIED
            elif c.command == wire.CHECKPOINT:
                # Not forwarded: the next step begin tells every participant (§3.8).
                self.checkpoint_next = self.p.out_dir is not None
                status = wire.ACK_APPLIED if self.checkpoint_next else wire.ACK_UNSUPPORTED
            elif c.command in (wire.SNAPSHOT, wire.SET):
                if not accepts(self.scene, c):
                    status = wire.ACK_UNSUPPORTED
                elif forwarded == FORWARD_AT_MOST:
                    status = wire.ACK_BUSY
                else:
                    forwarded += 1
                    self.forward(done, c)
                    status = wire.ACK_APPLIED
            else:
                status = wire.ACK_UNKNOWN_COMMAND
            self.acknowledge(done, c, status)
            if c.command == wire.STOP:
                time.sleep(ACK_LINGER)  # until the launcher and the bridge have the Ack
                return False
            if c.command == wire.PAUSE:
                self.paused = True
            elif c.command == wire.RESUME:
                self.paused = False

    def forward(self, done, c):
        """An accepted `snapshot` or `set`, unchanged, to both solvers (§3.8)."""

        def fill(h, address):
            self.p.header(h, done, 0.0, 0.0)
            ctypes.memmove(address, ctypes.addressof(c), ctypes.sizeof(wire.Control))

        self.command.publish(1, fill)

    def acknowledge(self, done, c, status):
        def fill(h, address):
            self.p.header(h, done, 0.0, 0.0)
            ack = wire.Ack.from_address(address)
            ack.seq, ack.step, ack.command = c.seq, done, c.command
            ack.status, ack.key, ack._pad = status, c.key, 0

        self.ack.publish(1, fill)

    def begin_step(self, step, start, checkpoint_after):
        """§3.4: step n's begin, with the scene's substeps, CHECKPOINT if asked for, and
        (checksums on) its checksum."""

        def fill(h, address):
            self.p.header(h, step, start, self.scene.dt)
            begin = wire.StepBegin.from_address(address)
            begin.flags = wire.STEP_CHECKPOINT if checkpoint_after else 0
            begin.substeps = self.scene.substeps
            if self.scene.checksums:
                h.checksum = wire.checksum(address, ctypes.sizeof(wire.StepBegin))

        self.begin.publish(1, fill)

    def couple(self, step, start):
        """§6.2 step 3: both rasters in (checked), constrained velocities out. Returns the
        summary fields and the compute time [ns]."""
        p = self.p
        dem_sample = p.receive(self.dem_raster, "the DEM raster")
        mpm_sample = p.receive(self.mpm_raster, "the MPM raster")
        t = time.perf_counter_ns()
        size = ctypes.sizeof(wire.RasterNode)
        p.check_message("grains/dem/raster", dem_sample, step, size)
        p.check_message("grains/mpm/raster", mpm_sample, step, size)
        # Read in place: views of the shared memory, valid until the samples are released.
        dem = wire.view(dem_sample.payload_ptr, dem_sample.header.number_of_elements, wire.RASTER_NODE)
        mpm = wire.view(mpm_sample.payload_ptr, mpm_sample.header.number_of_elements, wire.RASTER_NODE)
        for raster, service in ((dem, "grains/dem/raster"), (mpm, "grains/mpm/raster")):
            bad = first_unsorted(raster)
            if bad is not None:
                raise Halt(
                    f"{service}: step {step}: node indices must increase strictly; "
                    f"element {bad[0]} is node {bad[1]}"
                )
        nodes, v, (mass, momentum, ke) = constrain(dem, mpm)
        n_nodes = len(dem) + len(mpm)
        del dem, mpm
        dem_sample.delete()
        mpm_sample.delete()

        sent = {}

        def fill(h, address):
            out = wire.view(address, len(nodes), wire.NODE_VELOCITY)
            out["node"] = nodes
            out["velocity"] = v
            self.p.header(h, step, start, self.scene.dt)
            if self.scene.checksums:
                h.checksum = wire.checksum(address, len(nodes) * wire.NODE_VELOCITY.itemsize)
            sent["checksum"] = h.checksum

        self.velocities.publish(len(nodes), fill)
        compute_ns = time.perf_counter_ns() - t
        report = {
            "n_items": len(nodes),
            "n_nodes": n_nodes,
            "mass": mass,
            "momentum": momentum,
            "kinetic_energy": ke,
            "checksum": sent["checksum"],
        }
        return report, compute_ns

    def publish_summary(self, step, start, r, compute_ns, wait_ns):
        """§3.7: the coupler's summary of step n."""

        def fill(h, address):
            self.p.header(h, step, start, self.scene.dt)
            s = wire.Summary.from_address(address)
            s.role, s.status, s.step = wire.COUPLER, 0, step
            s.time = start + self.scene.dt
            s.n_items, s.n_nodes = r["n_items"], r["n_nodes"]
            s.mass = r["mass"]
            s.momentum[:] = r["momentum"]
            s.kinetic_energy = r["kinetic_energy"]
            s.checksum = r["checksum"]
            s.compute_ns, s.wait_ns = compute_ns, max(wait_ns, 0)

        self.summary.publish(1, fill)

    def stop(self, last):
        """§3.4: the STOP message after the last step taken (`last`, 0 if none)."""

        def fill(h, address):
            self.p.header(h, last + 1, last * self.scene.dt, self.scene.dt)
            begin = wire.StepBegin.from_address(address)
            begin.flags, begin.substeps = wire.STEP_STOP, 0

        self.begin.publish(1, fill)


def main(argv=None):
    """§8 and §7, as every participant (`participant.main`)."""
    return participant.main(
        wire.COUPLER, "grains_participants.coupler", "Coupler", lambda scene: None, lambda p, scene, _: Coupler(p, scene), argv
    )


if __name__ == "__main__":
    sys.exit(main())
