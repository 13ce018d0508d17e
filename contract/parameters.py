"""Parameters a plug-in declares, once: name, type, default, range, unit and what it does.

Planners (:class:`planners.base.Planner`) and controllers
(:mod:`.controller_specs`) declare theirs as a sequence of :class:`Param`; a
job's values are checked against it by :func:`check_values` (unknown names,
types, ranges), and the listings (``GET /api/v1/planners``, ``GET
/api/v1/controllers``) show :meth:`Param.to_dict`.  The older planner form, a
``defaults`` dict whose values' types are the parameters' types, becomes
parameters through :func:`params_from_defaults`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Sequence, Union

__all__ = ["TYPES", "Param", "ParamError", "Value", "check_values", "defaults_of", "params_from_defaults"]

#: a parameter's value: JSON's scalars
Value = Union[bool, int, float, str]
#: the types a parameter may have
TYPES = ("number", "integer", "boolean", "string")
_PYTHON_TYPES = {"number": (int, float), "integer": (int, float), "boolean": (bool,), "string": (str,)}


class ParamError(ValueError):
    """A parameter that is not declared (``unknown``), or a value its declaration refuses; ``param`` names it."""

    def __init__(self, param: str, message: str, *, unknown: bool = False) -> None:
        super().__init__(message)
        self.param = param
        self.unknown = unknown


@dataclass(frozen=True)
class Param:
    """One parameter: ``name`` (its unit as the suffix, by convention), ``unit``, ``default`` and the range
    ``[low, high]`` (None: unbounded on that side; ``low_exclusive``: ``low`` itself is refused) a value must lie in,
    ``doc`` (what it does) and its ``type`` (one of :data:`TYPES`: ``number``, ``integer`` — whole numbers only —,
    ``boolean``, ``string``).  ``compiled`` concerns controllers only: whether the compiled core reads it
    (:mod:`.controller_specs`)."""

    name: str
    unit: str = ""
    default: Value = 0.0
    low: Optional[float] = None
    high: Optional[float] = None
    doc: str = ""
    type: str = "number"
    compiled: bool = True
    low_exclusive: bool = False

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"parameter name {self.name!r} must be an identifier")
        if self.type not in TYPES:
            raise ValueError(f"parameter {self.name}: type {self.type!r} is not one of {', '.join(TYPES)}")
        if self.type in ("boolean", "string") and (self.low is not None or self.high is not None):
            raise ValueError(f"parameter {self.name}: a {self.type} has no range")
        problem = self.problem(self.default)
        if problem:
            raise ValueError(f"parameter {self.name}: its default {self.default!r} is not {problem}")

    @property
    def integer(self) -> bool:
        """Whether it takes whole numbers only."""
        return self.type == "integer"

    def describe(self) -> str:
        """What a value must be, in words: ``a number in [0.02, 1] (m)``, ``an integer >= 2``, ``true or false``."""
        if self.type == "boolean":
            return "true or false"
        if self.type == "string":
            return "a string"
        what = "an integer" if self.integer else "a number"
        low_bracket = "(" if self.low_exclusive else "["
        if self.low is not None and self.high is not None:
            what += f" in {low_bracket}{self.low:g}, {self.high:g}]"
        elif self.low is not None:
            what += f" {'>' if self.low_exclusive else '>='} {self.low:g}"
        elif self.high is not None:
            what += f" <= {self.high:g}"
        return what + (f" ({self.unit})" if self.unit else "")

    def problem(self, value: Any) -> str:
        """Why ``value`` is refused (what it must be, :meth:`describe`; ``finite`` for inf/NaN), or ``""``."""
        kinds = _PYTHON_TYPES[self.type]
        if isinstance(value, bool) != (self.type == "boolean") or not isinstance(value, kinds):
            return self.describe()
        if self.type in ("boolean", "string"):
            return ""
        if not math.isfinite(value):
            return "finite"
        if self.integer and float(value) != int(value):
            return self.describe()
        below = self.low is not None and (value <= self.low if self.low_exclusive else value < self.low)
        above = self.high is not None and value > self.high
        return self.describe() if below or above else ""

    def coerce(self, value: Value) -> Value:
        """An accepted ``value`` in the parameter's Python type (int, float, bool, str)."""
        if self.type == "integer":
            return int(value)
        if self.type == "number":
            return float(value)
        return value

    def to_dict(self) -> dict[str, Any]:
        """JSON form (what the listings show): ``name``, ``unit``, ``default``, ``range`` ``[low, high]`` (null:
        unbounded), ``description``; ``type`` unless it is ``number``, ``integer`` and ``low_exclusive`` only
        when true (a number parameter's form is the controllers' listing's as it always was)."""
        out: dict[str, Any] = {"name": self.name, "unit": self.unit, "default": self.default,
                               "range": [self.low, self.high], "description": self.doc}
        if self.type != "number":
            out["type"] = self.type
        if self.integer:
            out["integer"] = True
        if self.low_exclusive:
            out["low_exclusive"] = True
        return out


def check_values(declared: Optional[Sequence[Param]], given: Optional[Mapping[str, Any]], *, owner: str,
                 label: str) -> dict[str, Any]:
    """``given`` over the defaults of ``declared``, each value checked and in its parameter's type.

    ``declared`` None accepts any values unchecked.  :class:`ParamError` for the first problem: an
    undeclared name (``<owner> has no parameter 'x' (parameters: a, b)``, ``owner`` e.g. ``planner 'prm'``)
    or a refused value (``<label><name> must be <what>, got <value>``, ``label`` e.g. ``parameter prm.``).
    """
    values = dict(given or {})
    if declared is None:
        return values
    known = {p.name: p for p in declared}
    for key in values:
        if key not in known:
            allowed = ", ".join(sorted(known)) or "none"
            raise ParamError(str(key), f"{owner} has no parameter {key!r} (parameters: {allowed})", unknown=True)
    out: dict[str, Any] = {}
    for p in declared:
        value = values.get(p.name, p.default)
        problem = p.problem(value)
        if problem:
            raise ParamError(p.name, f"{label}{p.name} must be {problem}, got {value!r}")
        out[p.name] = p.coerce(value)
    return out


def params_from_defaults(defaults: Optional[Mapping[str, Any]]) -> Optional[tuple[Param, ...]]:
    """Parameters of the older ``defaults`` form: each value's Python type is the parameter's type, no range.
    None stays None (any parameters)."""
    if defaults is None:
        return None
    out = []
    for name, default in defaults.items():
        if isinstance(default, bool):
            kind = "boolean"
        elif isinstance(default, int):
            kind = "integer"
        elif isinstance(default, float):
            kind = "number"
        elif isinstance(default, str):
            kind = "string"
        else:
            raise TypeError(f"parameter {name}: a default is a bool, int, float or str, got {default!r}")
        out.append(Param(str(name), default=default, type=kind))
    return tuple(out)


def defaults_of(declared: Optional[Sequence[Param]]) -> Optional[dict[str, Value]]:
    """``{name: default}`` of ``declared`` (None: any parameters)."""
    return None if declared is None else {p.name: p.default for p in declared}
