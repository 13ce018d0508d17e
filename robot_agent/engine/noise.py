"""Counter-based random numbers: replayable noise for many robots at once.

Every random number the field emulation draws is a pure function of
``(key, counter, channel)``: ``key`` identifies one robot's run (derived from
the seed, see :func:`path_key`), ``counter`` is the control step since the
path started and ``channel`` says what the number is for (track noise,
tracker noise, dropouts, ...).  So a run's noise depends neither on wall-clock
timing nor on what other robots in the same process do, and a run is
replayed exactly by giving the same seed.

The mixer is SplitMix64's finaliser (Steele, Lea and Flood 2014), applied
twice; uniform doubles take the top 53 bits; normals come from Box-Muller.
The scalar functions are compiled (numba) and called by the simulation's
kernels; :func:`uniforms` and :func:`normals` are their array versions.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from .compiled import kernel

__all__ = ["box_muller", "mix64", "normals", "path_key", "uniform", "uniforms"]

# numba promotes uint64 mixed with int64 to float64: every constant is a uint64.
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_MASK = (1 << 64) - 1


@kernel
def mix64(x: np.uint64) -> np.uint64:
    """SplitMix64 finaliser of a uint64 (wrapping arithmetic)."""
    z = np.uint64(x) + _GOLDEN
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


@kernel
def uniform(key: np.uint64, counter: int, channels: int, channel: int) -> float:
    """Uniform number in (0, 1) of ``channel`` (of ``channels``) at ``counter`` of run ``key``."""
    c = np.uint64(counter) * np.uint64(channels) + np.uint64(channel)
    z = mix64(np.uint64(key) ^ mix64(c))
    return (float(z >> _S11) + 0.5) * (1.0 / 9007199254740992.0)


@kernel
def box_muller(u1: float, u2: float) -> tuple[float, float]:
    """Two standard normals from two uniforms in (0, 1)."""
    r = math.sqrt(-2.0 * math.log(u1))
    phi = 2.0 * math.pi * u2
    return r * math.cos(phi), r * math.sin(phi)


@kernel
def _uniforms(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    out = np.empty((len(keys), channels))
    for i in range(len(keys)):
        for ch in range(channels):
            out[i, ch] = uniform(keys[i], counters[i], channels, ch)
    return out


def uniforms(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    """Uniform numbers in (0, 1), shape ``(N, channels)``, for ``keys`` and ``counters`` ``(N,)``."""
    return _uniforms(np.asarray(keys, dtype=np.uint64), np.asarray(counters, dtype=np.int64), int(channels))


@kernel
def _box_muller_rows(u: np.ndarray) -> np.ndarray:
    pairs = u.shape[1] // 2
    out = np.empty_like(u)
    for i in range(len(u)):
        for j in range(pairs):
            out[i, j], out[i, j + pairs] = box_muller(u[i, j], u[i, j + pairs])
    return out


def normals(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    """Standard normals ``(N, channels)``: :func:`box_muller` on pairs of :func:`uniforms` ``(u[j], u[j + pairs])``."""
    pairs = (channels + 1) // 2
    return _box_muller_rows(uniforms(keys, counters, 2 * pairs))[:, :channels]


def _scalar_mix(x: int) -> int:
    return int(mix64(np.uint64(x & _MASK)))


def path_key(seed: int, robot_id: str | None = None, path_count: int | None = None) -> int:
    """The 64-bit noise key of one run.

    Without ``robot_id`` the key depends on ``seed`` alone: an explicit
    per-path seed replays the same noise on any robot.  The agent's default
    derivation uses ``(agent seed, robot id, path count)``.
    """
    k = _scalar_mix(seed)
    if robot_id is not None:
        h = int.from_bytes(hashlib.blake2b(robot_id.encode(), digest_size=8).digest(), "little")
        k = _scalar_mix(k ^ h)
    if path_count is not None:
        k = _scalar_mix(k ^ _scalar_mix(path_count + 0x5EED))
    return k
