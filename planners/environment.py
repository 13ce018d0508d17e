"""Environment model (docs/design.md, "Environment file"): a rectangular field with rectangular blocks.

An environment file is JSON::

    {"name": "room", "size": [1.8, 1.8],
     "blocks": [{"x": 0.9, "y": 0.45, "w": 0.06, "h": 0.9, "angle": 0.0}, ...],
     "plans": [{"name": "A", "start": [0.3, 0.3, 0.0], "goal": [1.5, 1.5, 1.57]}],
     "moving_obstacles": [{"radius": 0.04, "waypoints": [[0.2, 1.2], [0.8, 1.2]], "speed": 0.05}]}

Blocks are rectangles given by centre (``x``, ``y``), size (``w`` along the
block's own x axis, ``h`` along its y axis) and rotation ``angle`` (radians,
counter-clockwise), all in metres in the field frame whose origin is the
lower-left corner.  The field boundary counts as an obstacle.  ``plans`` and
``description`` are optional extensions, and so are ``moving_obstacles``
(discs moving in experiment time, :mod:`planners.moving`); any other key is refused so typos are
caught early.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from .errors import InvalidEnvironment
from .fields import check_keys as _check_keys
from .fields import number as _number
from .moving import MovingObstacle, parse_moving_obstacles

__all__ = [
    "BLOCK_TOLERANCE_M",
    "Block",
    "Environment",
    "Plan",
    "builtin_names",
    "half_extents",
    "load_environment",
    "parse_environment",
]

MAX_BLOCKS = 1000
#: how far (m) a block may reach beyond the field (rounding on the wire); robots refuse more too
BLOCK_TOLERANCE_M = 0.001
MAX_FIELD_SIZE_M = 100.0
_TOP_KEYS = {"name", "size", "blocks", "plans", "description", "moving_obstacles"}
_BLOCK_KEYS = {"x", "y", "w", "h", "angle"}


@dataclass(frozen=True)
class Block:
    """A rectangular obstacle: centre ``x``, ``y`` (m), size ``w``, ``h`` (m), ``angle`` (rad)."""

    x: float
    y: float
    w: float
    h: float
    angle: float = 0.0

    def to_dict(self) -> dict[str, float]:
        return {"x": self.x, "y": self.y, "w": self.w, "h": self.h, "angle": self.angle}


@dataclass(frozen=True)
class Plan:
    """A named start/goal pair: poses are ``(x, y, theta)`` in metres and radians."""

    name: str
    start: tuple[float, float, float]
    goal: tuple[float, float, float]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "start": list(self.start), "goal": list(self.goal)}


@dataclass(frozen=True)
class Environment:
    """A field of ``size`` = (width, height) metres with ``blocks`` as obstacles."""

    name: str
    size: tuple[float, float]
    blocks: tuple[Block, ...] = ()
    plans: tuple[Plan, ...] = ()
    description: str = field(default="", compare=False)
    #: discs moving in experiment time (:mod:`planners.moving`); not in the static occupancy grid
    moving_obstacles: tuple[MovingObstacle, ...] = ()

    @property
    def width(self) -> float:
        return self.size[0]

    @property
    def height(self) -> float:
        return self.size[1]

    def plan(self, name: str) -> Plan:
        """Return the start/goal plan called ``name`` (raises ``KeyError`` naming the choices)."""
        for p in self.plans:
            if p.name == name:
                return p
        choices = ", ".join(p.name for p in self.plans) or "none"
        raise KeyError(f"environment {self.name!r} has no plan {name!r} (plans: {choices})")

    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready form accepted by :func:`parse_environment`."""
        out: dict[str, Any] = {
            "name": self.name,
            "size": list(self.size),
            "blocks": [b.to_dict() for b in self.blocks],
        }
        if self.plans:
            out["plans"] = [p.to_dict() for p in self.plans]
        if self.description:
            out["description"] = self.description
        if self.moving_obstacles:
            out["moving_obstacles"] = [o.to_dict() for o in self.moving_obstacles]
        return out


def _pose(value: Any, where: str) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) not in (2, 3):
        raise InvalidEnvironment(f"{where} must be [x, y] or [x, y, theta], got {value!r}")
    nums = [_number(v, f"{where}[{i}]") for i, v in enumerate(value)]
    return (nums[0], nums[1], nums[2] if len(nums) == 3 else 0.0)


def _block(obj: Any, i: int, size: tuple[float, float]) -> Block:
    where = f"blocks[{i}]"
    if not isinstance(obj, Mapping):
        raise InvalidEnvironment(f"{where} must be an object, got {type(obj).__name__}")
    _check_keys(obj, _BLOCK_KEYS, where)
    for key in ("x", "y", "w", "h"):
        if key not in obj:
            raise InvalidEnvironment(f"{where}.{key} is missing")
    x, y = _number(obj["x"], f"{where}.x"), _number(obj["y"], f"{where}.y")
    w, h = _number(obj["w"], f"{where}.w"), _number(obj["h"], f"{where}.h")
    angle = _number(obj.get("angle", 0.0), f"{where}.angle")
    if w <= 0:
        raise InvalidEnvironment(f"{where}.w must be > 0, got {w}")
    if h <= 0:
        raise InvalidEnvironment(f"{where}.h must be > 0, got {h}")
    if not (0.0 <= x <= size[0] and 0.0 <= y <= size[1]):
        raise InvalidEnvironment(
            f"{where} centre ({x}, {y}) must lie inside the field 0..{size[0]} x 0..{size[1]} m"
        )
    ex, ey = half_extents(w, h, angle)
    tol = BLOCK_TOLERANCE_M
    if x - ex < -tol or x + ex > size[0] + tol or y - ey < -tol or y + ey > size[1] + tol:
        raise InvalidEnvironment(
            f"{where} ({w} x {h} m at ({x}, {y}), angle {angle}) reaches beyond the field 0..{size[0]} x "
            f"0..{size[1]} m: the gripper cannot build it"
        )
    return Block(x, y, w, h, angle)


def half_extents(w: Any, h: Any, angle: Any) -> tuple[Any, Any]:
    """Half width and half height (m) of the axis-aligned box around a ``w`` x ``h`` rectangle rotated by
    ``angle`` (rad); numbers or arrays."""
    c, s = np.abs(np.cos(angle)), np.abs(np.sin(angle))
    return (w * c + h * s) / 2, (w * s + h * c) / 2


def parse_environment(data: Mapping[str, Any]) -> Environment:
    """Validate a decoded environment JSON object and build an :class:`Environment`.

    Raises :class:`InvalidEnvironment` naming the offending field.
    """
    if not isinstance(data, Mapping):
        raise InvalidEnvironment(f"environment must be a JSON object, got {type(data).__name__}")
    _check_keys(data, _TOP_KEYS, "environment")
    name = data.get("name")
    if not isinstance(name, str) or not name.strip():
        raise InvalidEnvironment("name must be a non-empty string")
    if len(name) > 100:
        raise InvalidEnvironment("name must be at most 100 characters")
    size_raw = data.get("size")
    if not isinstance(size_raw, (list, tuple)) or len(size_raw) != 2:
        raise InvalidEnvironment(f"size must be [width, height] in metres, got {size_raw!r}")
    size = (_number(size_raw[0], "size[0]"), _number(size_raw[1], "size[1]"))
    for i, s in enumerate(size):
        if not 0 < s <= MAX_FIELD_SIZE_M:
            raise InvalidEnvironment(f"size[{i}] must be in (0, {MAX_FIELD_SIZE_M}] m, got {s}")
    blocks_raw = data.get("blocks", [])
    if not isinstance(blocks_raw, list):
        raise InvalidEnvironment(f"blocks must be a list, got {type(blocks_raw).__name__}")
    if len(blocks_raw) > MAX_BLOCKS:
        raise InvalidEnvironment(f"blocks must have at most {MAX_BLOCKS} entries, got {len(blocks_raw)}")
    blocks = tuple(_block(b, i, size) for i, b in enumerate(blocks_raw))
    plans_raw = data.get("plans", [])
    if not isinstance(plans_raw, list):
        raise InvalidEnvironment(f"plans must be a list, got {type(plans_raw).__name__}")
    plans = []
    for i, p in enumerate(plans_raw):
        if not isinstance(p, Mapping):
            raise InvalidEnvironment(f"plans[{i}] must be an object")
        _check_keys(p, {"name", "start", "goal"}, f"plans[{i}]")
        pname = p.get("name", str(i + 1))
        if not isinstance(pname, str):
            raise InvalidEnvironment(f"plans[{i}].name must be a string")
        plans.append(
            Plan(pname, _pose(p.get("start"), f"plans[{i}].start"), _pose(p.get("goal"), f"plans[{i}].goal"))
        )
    description = data.get("description", "")
    if not isinstance(description, str):
        raise InvalidEnvironment("description must be a string")
    moving = parse_moving_obstacles(data.get("moving_obstacles", []), size)
    return Environment(name.strip(), size, blocks, tuple(plans), description, moving)


def builtin_names() -> list[str]:
    """Names of the environments shipped with the package (``room``, ``blocks``, ...)."""
    files = resources.files("planners").joinpath("data")
    return sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".json"))


def load_environment(spec: str | Path | Mapping[str, Any] | Environment) -> Environment:
    """Load an environment from a built-in name, a JSON file path, or a decoded JSON object.

    Raises :class:`InvalidEnvironment` when the name is unknown, the file is
    unreadable or not JSON, or the content is invalid.
    """
    if isinstance(spec, Environment):
        return spec
    if isinstance(spec, Mapping):
        return parse_environment(spec)
    text: str
    name = str(spec)
    if isinstance(spec, str) and name in builtin_names():
        text = resources.files("planners").joinpath("data", f"{name}.json").read_text("utf-8")
        source = f"built-in environment {name!r}"
    else:
        path = Path(spec)
        if not path.exists():
            raise InvalidEnvironment(
                f"unknown environment {name!r}: not a built-in ({', '.join(builtin_names())}) "
                "and no such file"
            )
        try:
            text = path.read_text("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InvalidEnvironment(f"cannot read environment file {name}: {exc}") from exc
        source = f"environment file {name}"
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise InvalidEnvironment(
            f"{source} is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}"
        ) from exc
    try:
        return parse_environment(data)
    except InvalidEnvironment as exc:
        raise InvalidEnvironment(f"{source}: {exc}") from exc
