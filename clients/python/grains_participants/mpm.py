"""An external grains MPM in Python: the continuum solver of a coupled (hybrid) run.

A small explicit MPM in numpy, written from protocol/README.md; it follows the protocol
exactly as the built-in `grains-mpm` does but does not reproduce its numbers (the built-in
one has a Drucker-Prager plasticity; this one is elastic). Attach it to a run that waits for
an external MPM:

    grains run tests/scenes/hybrid_block_2d.toml --external mpm
    # the launcher prints: <path>/grains-mpm --scene <S> --run-id <R> --out-dir <D>
    python -m grains_participants.mpm --scene <S> --run-id <R> --out-dir <D>

The method: material points seeded `mpm.points_per_axis` per cell and axis in every `mpm`
body and in the hybrid and continuum cells of every `hybrid` body (weight `coupling.weight`
in hybrid cells, 1 elsewhere: §3.9); the scene's shape functions (GIMP or quadratic
B-splines, §3.5); APIC transfer with the velocity gradient as affine matrix; a compressible
Neo-Hookean material (the scene's Young's modulus and Poisson's ratio, no plasticity);
gravity; the domain's outer three node layers and the scene's plane and box walls as grid
conditions. A point carries its weighted mass w m and volume w V (§3.5, §3.7).

What each part implements, in protocol/README.md:

- `main`: §8 (the arguments every participant binary takes) and §7 (exit codes);
- `Mpm.open_ports` / `Mpm.connected`: §5 (the MPM's ports and the peers it waits for);
- `Mpm.initial_zones`: §3.9 (the oracle's zone field, step 0, before "ready");
- `Mpm.run`: §6.2 (the macro-step as a follower) and §6.3 (STOP);
- `Mpm.apply_commands`: §3.8 (commands the coupler forwarded on `step/command`);
- `Solver.predict` / `Mpm.send_raster`: §3.5 (phase 1 and the raster);
- `Solver.finish`: §3.6 and §6.2 step 4 (constrained velocities, then phase 2);
- `Mpm.publish_summary`: §3.7 (the solver's summary);
- `Mpm.offer_view`: §3.8a (the optional view for the bridge);
- `Mpm.save` / `Mpm.restore` (with the `checkpoint` module): §6.4 (checkpoints, resuming).

Not supported (refused with exit code 2): an MPM alone (the time owner of an MPM-only run),
synthetic test scenes, adaptive oracles (`oracle.kind = "surface"` or `"layered"`, §3.10),
segment and drum walls.
"""

import ctypes
import io
import math
import sys
import time
import tomllib

import numpy as np

from . import checkpoint, wire
from . import participant
from .participant import Halt
from .scene import SceneError

#: The outer node layers of every non-periodic domain face are its wall (as the built-in MPM).
DOMAIN_WALL_NODES = 3
#: Views: at most this often and this many points (§3.8a).
VIEW_PERIOD = 0.2
VIEW_MAX = 5000


def _vec(v, dim):
    a = np.zeros(dim)
    if v is not None:
        a[: min(dim, len(v))] = v[:dim]
    return a


class MpmScene:
    """What this MPM reads from the run's copy of the scene (besides `Scene`'s fields)."""

    def __init__(self, scene):
        doc = tomllib.loads(scene.data.decode("utf-8"))
        path = scene.path
        dim = self.dim = scene.dimension
        if "synthetic" in doc:
            raise SceneError(f"{path}: a synthetic test scene: this example MPM runs physics scenes only")
        bodies = [b for b in doc.get("body", []) if b.get("model") in ("mpm", "hybrid")]
        models = {b.get("model") for b in doc.get("body", [])}
        if not bodies:
            raise SceneError(f"{path}: the scene has no mpm or hybrid body")
        #: A coupled run (§2): the scene also has DEM material.
        self.coupled = bool(models & {"dem", "hybrid"})
        if not self.coupled:
            raise SceneError(
                f"{path}: an MPM-only scene: this example MPM runs only as a follower of a coupler "
                "(a scene with DEM material too), not as the time owner"
            )
        oracle = doc.get("oracle")
        #: §2: every physics scene with both materials has an oracle.
        self.has_oracle = True
        if oracle is not None and oracle.get("kind", "fixed") != "fixed":
            raise SceneError(f'{path}: oracle.kind = {oracle.get("kind")!r}: this example MPM takes no epochs (§3.10)')
        materials = {m["name"]: m for m in doc.get("material", [])}
        names = {b["material"] for b in bodies}
        if len(names) != 1:
            raise SceneError(f"{path}: mpm bodies of materials {sorted(names)}: one MPM material per scene")
        material = materials[names.pop()]
        if "mpm" not in material:
            raise SceneError(f"{path}: material {material['name']!r} has no [material.mpm]")
        mm = material["mpm"]
        young, poisson = float(mm["young"]), float(mm["poisson"])
        self.mu = young / (2.0 * (1.0 + poisson))
        self.lam = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson))
        self.packing = float(mm["packing"])
        #: Bulk density: packing fraction x grain density.
        self.rho = float(material["density"]) * self.packing

        domain = doc["domain"]
        self.origin = _vec(domain["min"], dim)
        self.top = _vec(domain["max"], dim)
        self.h = float(domain["cell_size"])
        periodic = domain.get("periodic", [False] * 3)
        self.periodic = np.array([bool(periodic[k]) if k < len(periodic) else False for k in range(dim)])
        #: §3.5: ceil((max - min) / h) + 1 nodes per axis; 1 on the unused axis in 2D.
        self.nodes = np.array([math.ceil((self.top[k] - self.origin[k]) / self.h) + 1 for k in range(dim)], dtype=np.int64)
        #: Along a periodic axis node n - 1 is node 0: indices are taken modulo the period.
        self.period = np.where(self.periodic, self.nodes - 1, 0)

        mpm = doc.get("mpm", {})
        self.per_axis = int(mpm.get("points_per_axis", 2))
        self.kernel = mpm.get("kernel", "gimp")
        if self.kernel not in ("gimp", "bspline"):
            raise SceneError(f"{path}: mpm.kernel = {self.kernel!r}")
        #: GIMP half-width over h (§3.5).
        self.gimp_l = 0.5 / self.per_axis
        self.domain_sticky = mpm.get("domain_walls", "slip") == "sticky"
        self.gravity = _vec(doc.get("gravity"), dim)
        self.weight = float(doc.get("coupling", {}).get("weight", 0.5))

        self.walls = []
        for k, w in enumerate(doc.get("wall", [])):
            kind = w.get("kind")
            wall = {
                "kind": kind,
                "velocity": _vec(w.get("velocity"), dim),
                "friction": float(w.get("friction", 0.0)),
                "sticky": bool(w.get("sticky", False)),
                "since": 0.0,
            }
            if kind == "plane":
                n = _vec(w["normal"], dim)
                wall["point"], wall["normal"] = _vec(w["point"], dim), n / np.linalg.norm(n)
            elif kind == "box":
                wall["min"], wall["max"] = _vec(w["min"], dim), _vec(w["max"], dim)
            else:
                raise SceneError(f"{path}: wall.{k}.kind = {kind!r}: this example MPM has plane and box walls only")
            self.walls.append(wall)

        self.bodies = []
        for b in bodies:
            body = {"model": b["model"], "shape": b["shape"], "velocity": _vec(b.get("velocity"), dim)}
            if b["shape"] == "box":
                body["min"], body["max"] = _vec(b["min"], dim), _vec(b["max"], dim)
            elif b["shape"] == "ball":
                body["center"], body["radius"] = _vec(b["center"], dim), float(b["radius"])
            else:
                raise SceneError(f"{path}: body shape {b['shape']!r}")
            if float(b.get("confining_pressure", 0.0)) > 0.0:
                raise SceneError(f"{path}: confining pressure: not in this example MPM")
            self.bodies.append(body)


def wall_offset(wall, t):
    """How far a wall has moved since the scene's start at time t (it moves at its velocity)."""
    return wall.get("shift", 0.0) + wall["velocity"] * (t - wall["since"])


def behind(wall, x, t):
    """Whether positions x (n x dim) lie behind (inside) a wall at time t."""
    d = wall_offset(wall, t)
    if wall["kind"] == "plane":
        return (x - (wall["point"] + d)) @ wall["normal"] <= 0.0
    return np.all((x >= wall["min"] + d) & (x <= wall["max"] + d), axis=1)


class ZoneField:
    """§3.9: the zone of every listed cell; material in a cell not listed is discrete."""

    def __init__(self, ms, cells):
        self.ms = ms
        self.cells = np.maximum(ms.nodes - 1, 1)
        self.index = np.asarray(cells["cell"], dtype=np.int64).copy()
        self.zone = np.asarray(cells["zone"], dtype=np.int64).copy()
        if len(self.index) > 1 and np.any(self.index[1:] <= self.index[:-1]):
            raise Halt("grains/oracle/zones: cell indices must increase strictly")

    def zone_at(self, x):
        ms = self.ms
        ijk = np.floor((x - ms.origin) / ms.h).astype(np.int64)
        ijk = np.where(ms.periodic, np.mod(ijk, np.maximum(ms.period, 1)), ijk)
        inside = np.all((ijk >= 0) & (ijk < self.cells), axis=1)
        cell = np.zeros(len(x), dtype=np.int64)
        stride = 1
        for k in range(ms.dim):
            cell += ijk[:, k] * stride
            stride *= self.cells[k]
        at = np.searchsorted(self.index, cell)
        at_c = np.minimum(at, max(len(self.index) - 1, 0))
        listed = inside & (len(self.index) > 0) & (self.index[at_c] == cell) if len(self.index) else np.zeros(len(x), bool)
        out = np.full(len(x), wire.ZONE_DISCRETE)
        out[listed] = self.zone[at_c[listed]]
        return out


class Solver:
    """The material points and one explicit MPM step, split at the coupling point."""

    def __init__(self, ms, zones):
        self.ms = ms
        dim, h = ms.dim, ms.h
        spacing = h / ms.per_axis
        volume = spacing**dim
        xs, vs, ws = [], [], []
        for b in ms.bodies:
            lo, hi = (b["min"], b["max"]) if b["shape"] == "box" else (b["center"] - b["radius"], b["center"] + b["radius"])
            axes = [
                ms.origin[k] + (np.arange(math.floor((lo[k] - ms.origin[k]) / spacing), math.ceil((hi[k] - ms.origin[k]) / spacing)) + 0.5) * spacing
                for k in range(dim)
            ]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
            if b["shape"] == "box":
                keep = np.all((grid >= lo) & (grid < hi), axis=1)
            else:
                keep = np.sum((grid - b["center"]) ** 2, axis=1) < b["radius"] ** 2
            for w in ms.walls:
                keep &= ~behind(w, grid, 0.0)
            x = grid[keep]
            weight = np.ones(len(x))
            if b["model"] == "hybrid":
                z = zones.zone_at(x)
                x, weight = x[z != wire.ZONE_DISCRETE], np.where(z == wire.ZONE_HYBRID, ms.weight, 1.0)[z != wire.ZONE_DISCRETE]
            xs.append(x)
            ws.append(weight)
            vs.append(np.tile(b["velocity"], (len(x), 1)))
        self.x = np.concatenate(xs)
        self.v = np.concatenate(vs)
        n = len(self.x)
        #: The weighted mass and volume: w m, w V (the share of the mixture the points carry).
        self.m = ms.rho * volume * np.concatenate(ws)
        self.vol = volume * np.concatenate(ws)
        self.F = np.tile(np.eye(dim), (n, 1, 1))
        self.C = np.zeros((n, dim, dim))
        self.time = 0.0
        self.stencil = None

    # -- shape functions -------------------------------------------------------------------

    def _weights_1d(self, d):
        """Weights and their derivatives (per cell) at signed distances d (in cells)."""
        a = np.abs(d)
        s = np.sign(d)
        if self.ms.kernel == "bspline":
            w = np.where(a < 0.5, 0.75 - d * d, np.where(a < 1.5, 0.5 * (1.5 - a) ** 2, 0.0))
            g = np.where(a < 0.5, -2.0 * d, np.where(a < 1.5, -(1.5 - a) * s, 0.0))
        else:
            l = self.ms.gimp_l
            w = np.where(
                a < l,
                1.0 - (d * d + l * l) / (2.0 * l),
                np.where(a < 1.0 - l, 1.0 - a, np.where(a < 1.0 + l, (1.0 + l - a) ** 2 / (4.0 * l), 0.0)),
            )
            g = np.where(
                a < l,
                -d / l,
                np.where(a < 1.0 - l, -s, np.where(a < 1.0 + l, -s * (1.0 + l - a) / (2.0 * l), 0.0)),
            )
        return w, g

    def _stencil(self):
        """Every (point, node) pair of the 3^dim stencils: node index (§3.5), weight N_ip,
        gradient, x_i - x_p; and the sorted nodes they touch."""
        ms = self.ms
        dim, h, n = ms.dim, ms.h, len(self.x)
        xi = (self.x - ms.origin) / h
        base = np.floor(xi + 0.5).astype(np.int64) - 1
        w1, g1 = [], []
        for o in range(3):
            d = xi - (base + o)
            w, g = self._weights_1d(d)
            w1.append(w)
            g1.append(g)
        offsets = np.stack(np.meshgrid(*[np.arange(3)] * dim, indexing="ij"), axis=-1).reshape(-1, dim)
        S = len(offsets)
        N = np.ones((n, S))
        grad = np.ones((n, S, dim))
        ijk = np.empty((n, S, dim), dtype=np.int64)
        for s, off in enumerate(offsets):
            for k in range(dim):
                N[:, s] *= w1[off[k]][:, k]
                for a in range(dim):
                    grad[:, s, a] *= (g1[off[k]][:, k] / h) if a == k else w1[off[k]][:, k]
                ijk[:, s, k] = base[:, k] + off[k]
        r = ijk * h + ms.origin - self.x[:, None, :]
        wrapped = np.where(ms.periodic, np.mod(ijk, np.maximum(ms.period, 1)), ijk)
        if np.any((wrapped < 0) | (wrapped >= ms.nodes)):
            raise Halt("a material point's stencil left the grid: material driven into the domain's edge")
        node = np.zeros((n, S), dtype=np.int64)
        stride = 1
        for k in range(dim):
            node += wrapped[:, :, k] * stride
            stride *= ms.nodes[k]
        nodes, inverse = np.unique(node.ravel(), return_inverse=True)
        return nodes, inverse, N.ravel(), grad.reshape(-1, dim), r.reshape(-1, dim)

    # -- the grid conditions -------------------------------------------------------------

    def _walls(self, nodes, v):
        """The domain's wall layers and the scene's walls on node velocities v (in place)."""
        ms = self.ms
        ijk = np.empty((len(nodes), ms.dim), dtype=np.int64)
        rest = nodes.copy()
        for k in range(ms.dim):
            ijk[:, k] = rest % ms.nodes[k]
            rest //= ms.nodes[k]
        for k in range(ms.dim):
            if ms.periodic[k]:
                continue
            for layer, normal in ((ijk[:, k] < DOMAIN_WALL_NODES, 1.0), (ijk[:, k] >= ms.nodes[k] - DOMAIN_WALL_NODES, -1.0)):
                if ms.domain_sticky:
                    v[layer] = 0.0
                else:  # slip: no velocity into the wall
                    into = layer & (v[:, k] * normal < 0.0)
                    v[into, k] = 0.0
        x = ijk * ms.h + ms.origin
        for w in ms.walls:
            inside = behind(w, x, self.time)
            if not inside.any():
                continue
            vw = w["velocity"]
            if w["kind"] == "box" or w["sticky"]:
                v[inside] = vw
                continue
            n = w["normal"]
            rel = v[inside] - vw
            vn = rel @ n
            approaching = vn < 0.0
            tangential = rel - vn[:, None] * n
            speed = np.linalg.norm(tangential, axis=1)
            # Coulomb: the tangential slip slows by friction x the normal velocity removed.
            scale = np.where(speed > 0.0, np.maximum(0.0, 1.0 - w["friction"] * np.abs(vn) / np.where(speed > 0, speed, 1.0)), 0.0)
            fixed = vw + tangential * scale[:, None]
            rel_out = np.where(approaching[:, None], fixed, v[inside])
            v[inside] = rel_out

    # -- the step ------------------------------------------------------------------------

    def kirchhoff(self):
        """Compressible Neo-Hookean Kirchhoff stress tau = mu (F F^T - I) + lambda ln J I."""
        ms = self.ms
        J = np.linalg.det(self.F)
        if np.any(~(J > 0.0)):
            raise Halt(f"MPM step at t = {self.time:.6e} s: a point was inverted (det F <= 0); the step is too large")
        eye = np.eye(ms.dim)
        return ms.mu * (self.F @ np.swapaxes(self.F, 1, 2) - eye) + (ms.lam * np.log(J))[:, None, None] * eye

    def predict(self, dt, gravity):
        """Phase 1: P2G (APIC), forces, the grid update with gravity and the walls. Returns
        the raster: node, mass, momentum m_i v_i of the updated velocity (§3.5)."""
        ms = self.ms
        dim = ms.dim
        nodes, inv, N, grad, r = self._stencil()
        self.stencil = (nodes, inv, N, grad)
        S = len(N) // len(self.x)
        m = np.repeat(self.m, S) * N
        vp = np.repeat(self.v, S, axis=0) + np.einsum("pab,pb->pa", np.repeat(self.C, S, axis=0), r)
        tau = np.repeat(self.kirchhoff() * self.vol[:, None, None], S, axis=0)
        f = -np.einsum("pab,pb->pa", tau, grad)
        k = len(nodes)
        mass = np.bincount(inv, m, minlength=k)
        momentum = np.stack([np.bincount(inv, m * vp[:, a], minlength=k) for a in range(dim)], axis=1)
        force = np.stack([np.bincount(inv, f[:, a], minlength=k) for a in range(dim)], axis=1)
        has = mass > 0.0
        v = np.zeros((k, dim))
        v[has] = (momentum[has] + dt * force[has]) / mass[has, None] + dt * gravity
        self._walls(nodes, v)
        if not np.all(np.isfinite(v)):
            raise Halt(f"MPM step at t = {self.time:.6e} s: a node velocity is not finite")
        self.node_v = v
        self.has = has
        return nodes[has], mass[has], mass[has, None] * v[has]

    def finish(self, dt, shared, velocity):
        """The coupler's velocities replace those of the shared nodes; then phase 2: G2P
        (velocity and its gradient), deformation update, advection."""
        ms = self.ms
        dim = ms.dim
        nodes, inv, N, grad = self.stencil
        at = np.searchsorted(nodes, shared)
        ok = (at < len(nodes)) & (nodes[np.minimum(at, len(nodes) - 1)] == shared)
        ok &= self.has[np.minimum(at, len(nodes) - 1)]
        if not ok.all():
            bad = int(shared[~ok][0])
            raise Halt(f"the coupler constrained node {bad} where the MPM has no material")
        self.node_v[at] = velocity[:, :dim]
        n = len(self.x)
        vi = self.node_v[inv]
        self.v = np.einsum("ps,psa->pa", N.reshape(n, -1), vi.reshape(n, -1, dim))
        self.C = np.einsum("psa,psb->pab", vi.reshape(n, -1, dim), grad.reshape(n, -1, dim))
        self.F = (np.eye(dim) + dt * self.C) @ self.F
        self.x = self.x + dt * self.v
        if ms.periodic.any():
            length = ms.period * ms.h
            self.x = np.where(ms.periodic, ms.origin + np.mod(self.x - ms.origin, np.where(length > 0, length, 1.0)), self.x)
        # Points keep one cell between them and the outer nodes (their stencils stay inside).
        lo, hi = ms.origin + ms.h, ms.origin + ms.h * (ms.nodes - 2)
        outside = ~ms.periodic & ((self.x < lo) | (self.x > hi))
        if outside.any():
            raise Halt(f"MPM step at t = {self.time:.6e} s: material reached the domain's edge")
        self.time += dt
        self.stencil = None

    def totals(self):
        """§3.7: points, weighted mass, momentum, kinetic energy."""
        mass = float(np.sum(self.m))
        p = np.zeros(3)
        p[: self.ms.dim] = self.m @ self.v
        ke = float(0.5 * np.sum(self.m * np.sum(self.v * self.v, axis=1)))
        return len(self.x), mass, p, ke


class Mpm:
    """The MPM's ports and its loop as a follower of the coupler."""

    def __init__(self, participant, scene, ms):
        self.p = participant
        self.scene = scene
        self.ms = ms
        self.gravity = ms.gravity.copy()
        self.last_view = None
        #: The step in hand asks for a checkpoint after it (STEP_CHECKPOINT, §3.4).
        self.checkpoint_after = False

    def open_ports(self):
        """§5: every service of a coupled MPM (in the order the built-in one opens them)."""
        p = self.p
        self.begin = p.subscriber("grains/step/begin", wire.StepBegin)
        self.velocities = p.subscriber("grains/coupler/velocities", wire.NodeVelocity)
        self.raster = p.publisher("grains/mpm/raster", wire.RasterNode, initial_len=1024)
        self.summary = p.publisher("grains/run/summary", wire.Summary)
        self.command = p.subscriber("grains/step/command", wire.Control)
        # The view: published only while the bridge subscribes; nobody waits for it (§5).
        self.view = p.publisher("grains/mpm/view", wire.ViewPoint)
        self.zones = p.subscriber("grains/oracle/zones", wire.ZoneCell) if self.ms.has_oracle else None

    def connected(self):
        """§5: the coupler, the oracle and the launcher are connected."""
        return (
            self.begin.publisher_count() >= 1
            and self.command.publisher_count() >= 1
            and self.velocities.publisher_count() >= 1
            and self.raster.subscriber_count() >= 1
            and self.summary.subscriber_count() >= 1
            and (self.zones is None or self.zones.publisher_count() >= 1)
        )

    def initial_zones(self):
        """§3.9: the oracle's zone field of step 0 (checked), before "ready"."""
        sample = self.p.receive(self.zones, "the zone field")
        try:
            self.p.check_message("grains/oracle/zones", sample, 0, wire.ZONE_CELL.itemsize)
            cells = wire.view(sample.payload_ptr, sample.header.number_of_elements, wire.ZONE_CELL).copy()
        finally:
            sample.delete()
        return ZoneField(self.ms, cells)

    def run(self):
        """§5 then §6.2 as a follower until the STOP (§6.3)."""
        p = self.p
        p.join()
        self.open_ports()
        p.wait_until("the coupler, the oracle and the launcher", self.connected)
        zones = self.initial_zones() if self.zones is not None else ZoneField(self.ms, np.zeros(0, wire.ZONE_CELL))
        self.solver = Solver(self.ms, zones)
        if p.resume_dir is not None:
            self.restore(checkpoint.read(p.resume_dir, wire.MPM, p.scene_hash, p.resume_step))
        p.ready()
        while True:
            wait_start = time.perf_counter_ns()
            window = self.next_step()
            if window is None:
                return  # STOP: no step, nothing more sent, exit 0
            # Only once the step is in hand: after the last one the coupler may be exiting.
            p.watch_peers()
            self.step(window, time.perf_counter_ns() - wait_start)

    def next_step(self):
        """§3.4: the next step begin (protocol version, run id, checksum checked; its step
        adopted); None on STOP."""
        sample = self.p.receive(self.begin, "the next step")
        try:
            h = sample.user_header().contents
            self.p.check_message("grains/step/begin", sample, h.step, ctypes.sizeof(wire.StepBegin))
            if sample.header.number_of_elements < 1:
                raise Halt(f"grains/step/begin: step {h.step}: an empty message (one StepBegin expected)")
            b = wire.StepBegin.from_buffer_copy(ctypes.string_at(sample.payload_ptr, 8))
            window = (h.step, h.time, h.dt)
        finally:
            sample.delete()
        self.checkpoint_after = bool(b.flags & wire.STEP_CHECKPOINT)
        return None if b.flags & wire.STEP_STOP else window

    def step(self, window, wait_ns):
        step, start, dt = window
        t0 = time.perf_counter_ns()
        self.apply_commands(step)
        raster_checksum = self.send_raster(window)
        compute_ns = time.perf_counter_ns() - t0

        t1 = time.perf_counter_ns()
        sample = self.p.receive(self.velocities, "the constrained velocities")
        t2 = time.perf_counter_ns()
        try:
            self.p.check_message("grains/coupler/velocities", sample, step, wire.NODE_VELOCITY.itemsize)
            v = wire.view(sample.payload_ptr, sample.header.number_of_elements, wire.NODE_VELOCITY)
            # Copies: the view of the shared memory must not outlive the sample.
            shared, velocity = v["node"].astype(np.int64), v["velocity"].copy()
            del v
        finally:
            sample.delete()
        self.solver.finish(dt, shared, velocity)
        t3 = time.perf_counter_ns()
        wait_ns += t2 - t1
        compute_ns += t3 - t2
        if checkpoint.due(self.scene, step, self.checkpoint_after):
            checkpoint.write(self.p.out_dir, wire.MPM, self.p.scene_hash, step, self.save())
        self.publish_summary(window, raster_checksum, compute_ns, wait_ns)
        self.offer_view(window)

    def save(self):
        """§6.4: this MPM's payload: its points, time, gravity and walls, as numpy's .npz."""
        s, walls = self.solver, self.ms.walls
        arrays = {"x": s.x, "v": s.v, "m": s.m, "vol": s.vol, "F": s.F, "C": s.C, "time": np.array(s.time)}
        arrays["gravity"] = self.gravity
        for k, w in enumerate(walls):
            # Velocity, the shift a `set` left (scalar 0 before any), and since when.
            shift = np.broadcast_to(np.asarray(w.get("shift", 0.0), dtype=float), w["velocity"].shape)
            arrays[f"wall{k}"] = np.concatenate([w["velocity"], shift, [w["since"]]])
        out = io.BytesIO()
        np.savez(out, **arrays)
        return out.getvalue()

    def restore(self, payload):
        """The state of `save` back, in a solver just built from the scene."""
        with np.load(io.BytesIO(payload)) as a:
            s = self.solver
            s.x, s.v, s.m, s.vol, s.F, s.C = (a[k].copy() for k in ("x", "v", "m", "vol", "F", "C"))
            s.time = float(a["time"])
            self.gravity = a["gravity"].copy()
            dim = self.ms.dim
            for k, w in enumerate(self.ms.walls):
                saved = a[f"wall{k}"]
                w["velocity"], w["shift"], w["since"] = saved[:dim].copy(), saved[dim : 2 * dim].copy(), float(saved[2 * dim])

    def apply_commands(self, step):
        """§3.8: every command the coupler forwarded (its header not read), as after step - 1.
        One this MPM cannot carry out is logged and dropped (its Ack already said 0)."""
        while True:
            sample = self.command.receive(0.0)
            if sample is None:
                return
            c = None
            if sample.header.number_of_elements >= 1:
                c = wire.Control.from_buffer_copy(ctypes.string_at(sample.payload_ptr, 24))
            sample.delete()
            if c is None:
                continue
            why = self.command_one(c)
            if why is not None:
                print(f"grains_participants.mpm: command {c.command} (key {c.key}) not carried out: {why}", file=sys.stderr)

    def command_one(self, c):
        ms = self.ms
        if c.command == wire.SNAPSHOT:
            return "this example MPM writes no frames"
        if c.command != wire.SET:
            return "not a command for a solver"
        if 1 <= c.key <= 3:
            axis = c.key - 1
            if axis >= ms.dim:
                return f"gravity axis {axis} in a {ms.dim}D run"
            self.gravity[axis] = c.value
            return None
        if c.key >= 16 and (c.key - 16) % 4 < 3:
            w, axis = (c.key - 16) // 4, (c.key - 16) % 4
            if w >= len(ms.walls) or axis >= ms.dim:
                return f"no wall {w} axis {axis}"
            wall = ms.walls[w]
            # The wall stays where it is and moves at the new velocity from now on.
            now = self.solver.time
            wall["shift"] = wall_offset(wall, now)
            wall["since"] = now
            wall["velocity"] = wall["velocity"].copy()
            wall["velocity"][axis] = c.value
            return None
        return "no such parameter"

    def send_raster(self, window):
        """§6.2 step 2: phase 1, then the raster (sorted nodes, weighted mass and momentum),
        header step n with its checksum when checksums are on. Returns the checksum sent."""
        step, start, dt = window
        nodes, mass, momentum = self.solver.predict(dt, self.gravity)
        self.n_nodes = len(nodes)
        sent = {"checksum": 0}

        def fill(h, address):
            out = wire.view(address, len(nodes), wire.RASTER_NODE)
            out["node"] = nodes
            out["mass"] = mass
            out["momentum"] = 0.0
            out["momentum"][:, : self.ms.dim] = momentum
            self.p.header(h, step, start, dt)
            if self.scene.checksums:
                h.checksum = wire.checksum(address, len(nodes) * wire.RASTER_NODE.itemsize)
            sent["checksum"] = h.checksum

        self.raster.publish(len(nodes), fill)
        return sent["checksum"]

    def publish_summary(self, window, checksum, compute_ns, wait_ns):
        """§3.7: points, raster nodes sent, weighted mass, momentum and kinetic energy of the
        points after the step, the raster's checksum."""
        step, start, dt = window
        n, mass, momentum, ke = self.solver.totals()

        def fill(h, address):
            self.p.header(h, step, start, dt)
            s = wire.Summary.from_address(address)
            s.role, s.status, s.step = wire.MPM, 0, step
            s.time = start + dt
            s.n_items, s.n_nodes = n, self.n_nodes
            s.mass = mass
            s.momentum[:] = momentum.tolist()
            s.kinetic_energy = ke
            s.checksum = checksum
            s.compute_ns, s.wait_ns = max(compute_ns, 0), max(wait_ns, 0)

        self.summary.publish(1, fill)

    def offer_view(self, window):
        """§3.8a: a decimated view, at most 5 a second, only while someone subscribes."""
        now = time.monotonic()
        if self.last_view is not None and now - self.last_view < VIEW_PERIOD:
            return
        self.last_view = now
        if self.view.subscriber_count() == 0:
            return
        step, start, dt = window
        sol, dim = self.solver, self.ms.dim
        n = len(sol.x)
        stride = max(-(-n // VIEW_MAX), 1)
        pick = np.arange(0, n, stride)
        size = 0.5 * (sol.vol[pick] / 1.0) ** (1.0 / dim)

        def fill(h, address):
            out = wire.view(address, len(pick), wire.VIEW_POINT)
            out["id"] = pick
            out["position"] = 0.0
            out["position"][:, :dim] = sol.x[pick]
            out["velocity"] = 0.0
            out["velocity"][:, :dim] = sol.v[pick]
            out["size"] = size
            out["pressure"] = np.nan  # this example does not say (§3.8a allows it)
            self.p.header(h, step, start + dt, dt)
            h.flags = n

        self.view.publish(len(pick), fill)


def main(argv=None):
    """§8 and §7, as every participant (`participant.main`)."""
    return participant.main(wire.MPM, "grains_participants.mpm", "MPM", MpmScene, Mpm, argv)


if __name__ == "__main__":
    sys.exit(main())
