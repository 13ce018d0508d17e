"""Profile overrides: a field robot with other sensor noise or control inaccuracies, checked against physics.

An override is ``{"tracker_noise_xy_m": 0.003, "motor_time_constant_s": 0.3}``: keys of a profile's
``field`` section (see ``contract/profiles/*.json`` for what each means), values in SI units.  A study
varies them (docs/fidelity.md, "Noise studies"); a job carries them (``profile_overrides``) and its field
runs are the emulated field robot with them.  Every value must lie in :data:`OVERRIDE_LIMITS`.
"""

from __future__ import annotations

import copy
import difflib
import math
from typing import Any, Mapping

__all__ = ["OVERRIDE_LIMITS", "OverrideError", "apply_overrides", "check_overrides", "overrides_label"]

#: physical range (low, high; both included) of each overridable ``field`` parameter, SI units
OVERRIDE_LIMITS: dict[str, tuple[float, float]] = {
    "camera_rate_hz": (1.0, 200.0),
    "tracker_latency_s": (0.0, 1.0),
    "tracker_noise_xy_m": (0.0, 0.05),
    "tracker_noise_theta_rad": (0.0, 0.5),
    "tracker_bias_xy_m": (0.0, 0.05),
    "tracker_bias_length_m": (0.01, 3.6),
    "tracker_dropout_prob": (0.0, 0.9),
    "latency_compensation_s": (0.0, 1.0),
    "control_lead_s": (0.0, 1.0),
    "motor_time_constant_s": (0.0, 2.0),
    "wheel_noise_rel": (0.0, 1.0),
    "wheel_noise_abs_m_s": (0.0, 0.1),
    "wheel_noise_corr_s": (0.0, 2.0),
    "wheel_gain_mean": (0.1, 2.0),
    "wheel_bias_sigma": (0.0, 0.5),
    "dead_band_m_s": (0.0, 0.1),
    "track_width_factor": (1.0, 3.0),
}
_UNITS = {"hz": "Hz", "s": "s", "m": "m", "rad": "rad", "prob": "probability", "m_s": "m/s"}


class OverrideError(ValueError):
    """An override that is not a field parameter or lies outside its physical range; names the field."""


def _unit(key: str) -> str:
    for suffix in ("m_s", "hz", "rad", "prob", "s", "m"):
        if key.endswith("_" + suffix):
            return _UNITS[suffix]
    return ""


def check_overrides(overrides: Any, where: str = "profile_overrides") -> dict[str, float]:
    """``overrides`` as ``{name: float}`` if every name is an overridable field parameter and every value a
    finite number in its range (:data:`OVERRIDE_LIMITS`); else :class:`OverrideError` naming ``where.name``,
    the range and its unit, or the nearest parameter name."""
    if not isinstance(overrides, Mapping):
        raise OverrideError(f"{where} must be an object of field parameters, e.g. {{\"tracker_noise_xy_m\": 0.003}}")
    out: dict[str, float] = {}
    for key, value in overrides.items():
        if key not in OVERRIDE_LIMITS:
            near = difflib.get_close_matches(str(key), OVERRIDE_LIMITS, n=1, cutoff=0.6)
            hint = f" (did you mean {near[0]}?)" if near else f" (parameters: {', '.join(OVERRIDE_LIMITS)})"
            raise OverrideError(f"{where}: unknown field parameter {key!r}{hint}")
        lo, hi = OVERRIDE_LIMITS[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
                or not lo <= value <= hi:
            raise OverrideError(f"{where}.{key} must be a number in [{lo:g}, {hi:g}] ({_unit(key)}), got {value!r}")
        out[str(key)] = float(value)
    return out


def apply_overrides(profile: Mapping[str, Any], overrides: Mapping[str, float] | None) -> dict[str, Any]:
    """A copy of ``profile`` (a profile dict) with ``overrides`` (checked) in its ``field`` section."""
    out = copy.deepcopy(dict(profile))
    if overrides:
        out["field"] = {**out["field"], **check_overrides(overrides)}
    return out


def overrides_label(overrides: Mapping[str, float] | None) -> str:
    """A short name of a variant: ``shipped`` without overrides, else ``key=value,...`` sorted by key."""
    if not overrides:
        return "shipped"
    return ",".join(f"{k}={v:g}" for k, v in sorted(overrides.items()))
