"""The simulated arm's world: configuration (dataclass or TOML) and runtime state.

Frames and units: the manipulator base frame (origin on the shoulder, z up;
seed 000 stores obstacles "with sides aligned with the manipulator base
coordinate system"), metres, radians, kilograms, newtons, seconds.

* Obstacles are axis-aligned boxes, kept as seed 000's n x 6 array of rows
  (xmin, xmax, ymin, ymax, zmin, zmax); more can be added at run time.
* Objects are cubes of edge ``size`` with a mass; the gripper can hold one.
  A released object falls straight down and comes to rest on the highest
  obstacle top (or the floor) under its centre.  Objects are not obstacles:
  the planner checks the arm's links, and the object in the hand, against
  the boxes only, so the hand may pass through an object lying on the table
  (a bin is modelled, seed-000 style, by its circumscribing box).

Invalid values raise :class:`~linksim.ConfigError` naming the field.  Sans-I/O
apart from :meth:`WorldConfig.from_toml`, which reads the file it is given.
"""

from __future__ import annotations

import json
import math
import pathlib
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from linksim._errors import ConfigError

from ._kinematics import PUMA560, Array

__all__ = [
    "DEFAULT_WORLD",
    "MAX_OBJECTS",
    "MAX_OBSTACLES",
    "ObjectSpec",
    "ObstacleSpec",
    "World",
    "WorldConfig",
    "WorldObject",
]

MAX_OBSTACLES = 64
"""Bound on the obstacle array, run-time additions included.  Seed 000's arm
had twelve permanent obstacles; 64 leaves room for what sensors add while the
per-move collision check (20 points x 4 links x n boxes) stays well under a
millisecond."""

MAX_OBJECTS = 64
"""Bound on the objects in the world (the proximity search is linear in it)."""

Vec3 = tuple[float, float, float]


def _vec3(name: str, value: Any) -> Vec3:
    if (
        not isinstance(value, Sequence)
        or isinstance(value, str)
        or len(value) != 3
        or not all(isinstance(x, int | float) and math.isfinite(x) for x in value)
    ):
        raise ConfigError(f"{name} must be three finite numbers (m), got {value!r}")
    return (float(value[0]), float(value[1]), float(value[2]))


def _positive(name: str, value: Any, *, upper: float = math.inf) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and 0 < value <= upper):
        limit = "" if upper == math.inf else f" and <= {upper}"
        raise ConfigError(f"{name} must be a finite number > 0{limit}, got {value!r}")


@dataclass(frozen=True, slots=True)
class ObstacleSpec:
    """An axis-aligned box from ``minimum`` to ``maximum`` (m, base frame)."""

    name: str
    minimum: Vec3
    maximum: Vec3

    def __post_init__(self) -> None:
        object.__setattr__(self, "minimum", _vec3(f"obstacle {self.name!r} min", self.minimum))
        object.__setattr__(self, "maximum", _vec3(f"obstacle {self.name!r} max", self.maximum))
        for axis, lo, hi in zip("xyz", self.minimum, self.maximum, strict=True):
            if lo >= hi:
                raise ConfigError(
                    f"obstacle {self.name!r}: max {axis} ({hi}) must exceed min {axis} ({lo})"
                )

    @property
    def row(self) -> tuple[float, float, float, float, float, float]:
        """Seed 000's row: (xmin, xmax, ymin, ymax, zmin, zmax)."""
        lo, hi = self.minimum, self.maximum
        return (lo[0], hi[0], lo[1], hi[1], lo[2], hi[2])


@dataclass(frozen=True, slots=True)
class ObjectSpec:
    """A graspable cube: centre ``position`` (m), edge ``size`` (m), ``mass`` (kg)."""

    name: str
    position: Vec3
    size: float
    mass: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec3(f"object {self.name!r} position", self.position))
        _positive(f"object {self.name!r} size", self.size, upper=1.0)
        _positive(f"object {self.name!r} mass", self.mass, upper=1000.0)


def _joints6(value: Any) -> tuple[float, float, float, float, float, float]:
    if (
        not isinstance(value, Sequence)
        or isinstance(value, str)
        or len(value) != 6
        or not all(isinstance(x, int | float) and math.isfinite(x) for x in value)
    ):
        raise ConfigError(f"initial_joints must be six finite angles (rad), got {value!r}")
    q = tuple(float(x) for x in value)
    return (q[0], q[1], q[2], q[3], q[4], q[5])


@dataclass(frozen=True, slots=True)
class WorldConfig:
    """Everything the simulated arm needs to know about its world.

    Speeds: ``speed`` is the initial change-speed fraction (0, 1];
    ``max_joint_velocity`` (rad/s) is seed 000's maximum-allowed-velocity
    vector; ``cartesian_speed`` (m/s) is the Level-2 paths' hand speed at
    fraction 1; ``blend_time`` (s) is a path blend's default length.
    Sensors: ``proximity_range`` (m) of the wrist proximity sensors,
    ``weigh_noise`` (kg, standard deviation) of the weighing, drawn from a
    generator seeded with ``seed``.
    """

    obstacles: tuple[ObstacleSpec, ...] = ()
    objects: tuple[ObjectSpec, ...] = ()
    initial_joints: tuple[float, float, float, float, float, float] = (0.0,) * 6
    initial_opening: float = 0.08
    max_opening: float = 0.08
    speed: float = 1.0
    max_joint_velocity: tuple[float, float, float, float, float, float] = PUMA560.max_velocity
    cartesian_speed: float = 0.25
    blend_time: float = 0.2
    finger_speed: float = 0.05
    max_grip_force: float = 100.0
    proximity_range: float = 0.15
    weigh_noise: float = 0.0
    weigh_time: float = 0.5
    clearance: float = 0.01
    floor_z: float = -0.672
    control_rate_hz: float = 125.0
    telemetry_every: int = 10
    seed: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "objects", tuple(self.objects))
        if len(self.obstacles) > MAX_OBSTACLES:
            raise ConfigError(f"at most {MAX_OBSTACLES} obstacles, got {len(self.obstacles)}")
        if len(self.objects) > MAX_OBJECTS:
            raise ConfigError(f"at most {MAX_OBJECTS} objects, got {len(self.objects)}")
        object.__setattr__(self, "initial_joints", _joints6(self.initial_joints))
        v = self.max_joint_velocity
        if len(v) != 6:
            raise ConfigError(f"max_joint_velocity needs six values (rad/s), got {v!r}")
        for j, x in enumerate(v):
            _positive(f"max_joint_velocity[{j}]", x, upper=20.0)
        _positive("max_opening", self.max_opening, upper=0.5)
        if not (
            isinstance(self.initial_opening, int | float)
            and 0 <= self.initial_opening <= self.max_opening
        ):
            raise ConfigError(
                f"initial_opening must be in [0, max_opening={self.max_opening}] m, "
                f"got {self.initial_opening!r}"
            )
        _positive("speed", self.speed, upper=1.0)
        _positive("cartesian_speed", self.cartesian_speed, upper=5.0)
        _positive("blend_time", self.blend_time, upper=10.0)
        _positive("finger_speed", self.finger_speed, upper=5.0)
        _positive("max_grip_force", self.max_grip_force, upper=10000.0)
        _positive("proximity_range", self.proximity_range, upper=5.0)
        _positive("weigh_time", self.weigh_time, upper=60.0)
        _positive("control_rate_hz", self.control_rate_hz, upper=10000.0)
        for name in ("weigh_noise", "clearance"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value >= 0):
                raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")
        if not (isinstance(self.floor_z, int | float) and math.isfinite(self.floor_z)):
            raise ConfigError(f"floor_z must be a finite number (m), got {self.floor_z!r}")
        if not (isinstance(self.telemetry_every, int) and 1 <= self.telemetry_every <= 10000):
            raise ConfigError(
                f"telemetry_every must be an integer 1..10000, got {self.telemetry_every!r}"
            )
        if not isinstance(self.seed, int):
            raise ConfigError(f"seed must be an integer, got {self.seed!r}")
        names = [o.name for o in self.objects]
        if len(set(names)) != len(names):
            raise ConfigError(f"object names must be unique, got {names}")

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> WorldConfig:
        """Build from a parsed TOML document (see :meth:`from_toml` for the layout)."""
        known = {f.name for f in fields(cls)} - {"obstacles", "objects"}
        kwargs: dict[str, Any] = {k: v for k, v in data.items() if k in known}
        extra = sorted(k for k in data if k not in known | {"obstacles", "objects"})
        if extra:
            raise ConfigError(f"unknown world setting(s): {', '.join(extra)}")
        obstacles = []
        for i, o in enumerate(data.get("obstacles", [])):
            if not isinstance(o, Mapping) or set(o) - {"name"} != {"min", "max"}:
                raise ConfigError(f"obstacles[{i}] needs min and max (and an optional name)")
            obstacles.append(ObstacleSpec(str(o.get("name", f"obstacle{i}")), o["min"], o["max"]))
        objects = []
        for i, o in enumerate(data.get("objects", [])):
            if not isinstance(o, Mapping) or set(o) != {"name", "position", "size", "mass"}:
                raise ConfigError(f"objects[{i}] needs exactly name, position, size and mass")
            objects.append(ObjectSpec(str(o["name"]), o["position"], o["size"], o["mass"]))
        for key in ("initial_joints", "max_joint_velocity"):
            if key in kwargs and isinstance(kwargs[key], list):
                kwargs[key] = tuple(kwargs[key])
        return cls(obstacles=tuple(obstacles), objects=tuple(objects), **kwargs)

    @classmethod
    def from_toml(cls, source: str | pathlib.Path) -> WorldConfig:
        """Load a world from TOML text or a ``.toml`` file path.

        Layout: top-level scalar settings (the field names of this class;
        ``initial_joints`` in radians), ``[[obstacles]]`` tables with
        ``name``, ``min = [x, y, z]``, ``max = [x, y, z]``, and ``[[objects]]``
        tables with ``name``, ``position``, ``size``, ``mass``.
        """
        if isinstance(source, pathlib.Path):
            text = source.read_text()
        else:
            text = source
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"world TOML does not parse: {exc}") from exc
        return cls.from_mapping(data)

    def to_toml(self) -> str:
        """This configuration as TOML text that :meth:`from_toml` reads back equal."""

        def value(v: Any) -> str:
            if isinstance(v, bool):
                return "true" if v else "false"
            if isinstance(v, int | float):
                return repr(v)
            if isinstance(v, str):
                # JSON's string escapes are a subset of TOML basic strings'.
                return json.dumps(v)
            return "[" + ", ".join(value(x) for x in v) + "]"

        lines = [
            "# telelink arm world: linksim arm-server / demo / console --world FILE",
            "# Lengths in metres, angles in radians, times in seconds, masses in kg.",
        ]
        for f in fields(self):
            if f.name in ("obstacles", "objects"):
                continue
            setting = f"{f.name} = {value(getattr(self, f.name))}"
            lines.append(f"{setting.ljust(40)}  # {_WORLD_NOTES[f.name]}")
        if self.obstacles:
            lines += ["", "# Boxes the arm must not touch: min and max corners, m."]
        for o in self.obstacles:
            lines += ["", "[[obstacles]]", f"name = {value(o.name)}"]
            lines += [f"min = {value(o.minimum)}", f"max = {value(o.maximum)}"]
        if self.objects:
            lines += ["", "# Objects to grasp: centre position (m), cube size (m), mass (kg)."]
        for b in self.objects:
            lines += ["", "[[objects]]", f"name = {value(b.name)}"]
            lines += [f"position = {value(b.position)}", f"size = {value(b.size)}"]
            lines += [f"mass = {value(b.mass)}"]
        return "\n".join(lines) + "\n"


_WORLD_NOTES = {
    "initial_joints": "six joint angles at start, rad",
    "initial_opening": "finger opening at start, m",
    "max_opening": "widest finger opening, m",
    "speed": "initial speed fraction (CHANGE_SPEED), (0, 1]",
    "max_joint_velocity": "maximum allowed velocity per joint, rad/s",
    "cartesian_speed": "hand speed of Level-2 paths at speed 1, m/s",
    "blend_time": "default length of a path blend, s",
    "finger_speed": "finger closing speed, m/s",
    "max_grip_force": "largest grip force a command may ask, N",
    "proximity_range": "range of the wrist proximity sensors, m",
    "weigh_noise": "standard deviation of a weighing, kg (seeded by seed)",
    "weigh_time": "time a weighing takes, s",
    "clearance": "margin kept from obstacles, m",
    "floor_z": "height of the floor, m",
    "control_rate_hz": "servo rate of the simulation, Hz",
    "telemetry_every": "send telemetry every N servo steps",
    "seed": "seed of the weighing noise",
}
"""One line per scalar setting for :meth:`WorldConfig.to_toml`'s comments."""


DEFAULT_WORLD = WorldConfig(
    obstacles=(
        ObstacleSpec("ground", (-2.0, -2.0, -0.772), (2.0, 2.0, -0.672)),
        ObstacleSpec("table", (0.25, -0.75, -0.672), (0.95, 0.75, -0.35)),
        ObstacleSpec("bin", (0.30, -0.53, -0.35), (0.46, -0.37, -0.25)),
        ObstacleSpec("rack", (-0.45, 0.25, -0.672), (-0.25, 0.55, 0.40)),
    ),
    objects=(
        ObjectSpec("rock", (0.55, 0.15, -0.315), 0.07, 0.85),
        ObjectSpec("pebble", (0.75, -0.30, -0.33), 0.04, 0.12),
    ),
    # Hand pointing down 0.4 m in front of the shoulder, elbow up.
    initial_joints=(0.0, math.radians(90), math.radians(-200), 0.0, math.radians(-70), 0.0),
    weigh_noise=0.002,
    seed=7,
)
"""A table with a rock, a pebble and a bin, a rack beside the arm, the ground below."""


@dataclass(slots=True)
class WorldObject:
    """An object's run-time state (its centre moves with the hand while grasped)."""

    name: str
    position: Array
    size: float
    mass: float


class World:
    """The mutable world: the obstacle array and the objects.  Pure numpy."""

    def __init__(self, config: WorldConfig) -> None:
        self.config = config
        self._rows: list[tuple[float, ...]] = [o.row for o in config.obstacles]
        self.obstacle_names: list[str] = [o.name for o in config.obstacles]
        self.objects: list[WorldObject] = [
            WorldObject(o.name, np.array(o.position, dtype=np.float64), o.size, o.mass)
            for o in config.objects
        ]
        self._obstacles = np.array(self._rows, dtype=np.float64).reshape(-1, 6)

    @property
    def obstacles(self) -> Array:
        """Seed 000's n x 6 obstacle array (a copy)."""
        return self._obstacles.copy()

    def add_obstacle(self, minimum: Vec3, maximum: Vec3, name: str = "") -> int:
        """Append a box; returns its row index.  Raises ConfigError when full or malformed."""
        if len(self._rows) >= MAX_OBSTACLES:
            raise ConfigError(f"the obstacle array is full ({MAX_OBSTACLES} boxes)")
        spec = ObstacleSpec(name or f"added{len(self._rows)}", minimum, maximum)
        self._rows.append(spec.row)
        self.obstacle_names.append(spec.name)
        self._obstacles = np.array(self._rows, dtype=np.float64).reshape(-1, 6)
        return len(self._rows) - 1

    def between_fingers(self, p: Array, s: Array, a: Array, opening: float) -> int | None:
        """The object a closing gripper at P (fingers along S, approach A) would hold.

        An object is between the fingers when it fits the opening along S
        and the plane of the fingertips (through P, normal to A) and the
        fingers' width both cut through it; 5 mm of slack for each.
        """
        n = np.cross(s, a)
        best: tuple[float, int] | None = None
        for i, obj in enumerate(self.objects):
            d = obj.position - p
            half = obj.size / 2.0
            fits = abs(float(d @ s)) + half <= opening / 2.0 + 0.005
            level = abs(float(d @ a)) <= half + 0.005 and abs(float(d @ n)) <= half + 0.005
            if fits and level:
                dist = float(np.linalg.norm(d))
                if best is None or dist < best[0]:
                    best = (dist, i)
        return None if best is None else best[1]

    def nearest_in_range(self, p: Array, reach: float, exclude: int | None) -> int | None:
        """The object whose surface is nearest P within ``reach`` m (proximity sensors)."""
        best: tuple[float, int] | None = None
        for i, obj in enumerate(self.objects):
            if i == exclude:
                continue
            dist = float(np.linalg.norm(obj.position - p)) - obj.size / 2.0
            if dist <= reach and (best is None or dist < best[0]):
                best = (dist, i)
        return None if best is None else best[1]

    def rest_height(self, index: int) -> float:
        """Where a released object's centre comes to rest (z): the highest support below it."""
        obj = self.objects[index]
        x, y, z = (float(c) for c in obj.position)
        bottom = z - obj.size / 2.0
        support = self.config.floor_z
        for xmin, xmax, ymin, ymax, _zmin, zmax in self._rows:
            if xmin <= x <= xmax and ymin <= y <= ymax and zmax <= bottom + 1e-9:
                support = max(support, zmax)
        return support + obj.size / 2.0
