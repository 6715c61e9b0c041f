"""What a time owner reads from the run's copy of the scene file.

Implements protocol/README.md §6.1 (steps, dt, substeps), plus what the coupler needs to
check control commands (§3.8: the run's dimension and walls) and to know its peers (§2: a
physics scene with both materials has an oracle, a synthetic test scene never; §4: whether
checksums are on).
"""

import math
import tomllib


class SceneError(Exception):
    """Bad input: the participant exits with code 2 (§7)."""


class Scene:
    """The fields of a scene file that a coupler uses."""

    def __init__(self, path):
        self.path = path
        with open(path, "rb") as f:
            #: The file's bytes, unchanged: their hash is the run's (§4, §6.1).
            self.data = f.read()
        try:
            doc = tomllib.loads(self.data.decode("utf-8"))
        except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
            raise SceneError(f"{path}: {e}") from e
        run = doc.get("run", {})
        coupling = doc.get("coupling", {})
        synthetic = doc.get("synthetic")

        if "dt" not in run:
            raise SceneError(f"{path}: run.dt is missing")
        self.dt = float(run["dt"])
        if "steps" in run:
            self.steps = int(run["steps"])
        elif "duration" in run:
            # Rounded to the nearest integer, halves away from zero, at least 1 (§6.1).
            # (Python's round() rounds halves to even: not the same.)
            x = float(run["duration"]) / self.dt
            n = math.floor(x)
            if x - n >= 0.5:
                n += 1
            self.steps = max(int(n), 1)
        else:
            raise SceneError(f"{path}: give run.steps or run.duration")

        substeps = coupling.get("substeps", 10)
        if not isinstance(substeps, int):
            raise SceneError(
                f'{path}: coupling.substeps = {substeps!r}: "auto" is resolved by `grains run`, '
                "pass the run's copy of the scene (out/<scene>/<run-id>/scene.toml)"
            )
        self.substeps = substeps

        if run.get("dimension") not in (2, 3):
            raise SceneError(f"{path}: run.dimension must be 2 or 3")
        self.dimension = run["dimension"]
        #: `[[wall]]` tables, numbered from 0 in file order (`set` keys of §3.8).
        self.n_walls = len(doc.get("wall", []))
        #: Every physics scene with a coupler has an oracle; a synthetic test scene none (§2).
        self.has_oracle = synthetic is None
        #: Macro-steps between checkpoints (§6.4); 0: none.
        self.checkpoint_every = int(doc.get("output", {}).get("checkpoint_every", 0))
        #: Checksums are computed and verified unless `synthetic.checksum = false` (§4).
        self.checksums = synthetic is None or bool(synthetic.get("checksum", True))
