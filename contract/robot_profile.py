"""Robot profiles: physical and controller parameters as data (``contract/profiles/*.json``).

Every value is in SI units and carries a documented reason in the file's
``notes``.  Load one with :func:`load_profile`; list them with
:func:`profile_names`.
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources
from typing import Any

__all__ = ["DEFAULT_PROFILE", "load_profile", "profile_for_platform", "profile_names"]

DEFAULT_PROFILE = "bebot"


def profile_names() -> list[str]:
    """Names of the shipped profiles (``bebot``, ``khepera3``)."""
    return list(_shipped())


@lru_cache(maxsize=None)
def _shipped() -> tuple[str, ...]:
    files = resources.files("contract").joinpath("profiles")
    return tuple(sorted(p.name[:-5] for p in files.iterdir() if p.name.endswith(".json")))


@lru_cache(maxsize=None)
def _text(name: str) -> str:
    # package data, read once per process: every simulated run loads its robot's profile
    return resources.files("contract").joinpath("profiles", f"{name}.json").read_text("utf-8")


def load_profile(name: str = DEFAULT_PROFILE) -> dict[str, Any]:
    """The profile called ``name`` as a dict; ``ValueError`` naming the choices if unknown."""
    if name not in _shipped():
        raise ValueError(f"unknown robot profile {name!r} (profiles: {', '.join(_shipped())})")
    return json.loads(_text(name))  # a fresh dict: callers may change theirs


@lru_cache(maxsize=64)
def profile_for_platform(platform: str) -> str:
    """The name of the shipped profile whose ``platform`` is ``platform`` (``BeBot`` -> ``bebot``); the default
    profile when none is."""
    for name in _shipped():
        if load_profile(name).get("platform") == platform:
            return name
    return DEFAULT_PROFILE
