"""Counter-based random numbers: replayable noise for many robots at once, without loops.

Every random number the field emulation draws is a pure function of
``(key, counter, channel)``: ``key`` identifies one robot's run (derived from
the seed, see :func:`path_key`), ``counter`` is the control step since the
path started and ``channel`` says what the number is for (track noise,
tracker noise, dropouts, ...).  So a run's noise depends neither on wall-clock
timing nor on what other robots in the same process do, and a run is
replayed exactly by giving the same seed.

The mixer is SplitMix64's finaliser (Steele, Lea and Flood 2014), applied
twice; uniform doubles take the top 53 bits; normals come from Box-Muller.
"""

from __future__ import annotations

import hashlib

import numpy as np

__all__ = ["box_muller", "mix64", "normals", "path_key", "uniforms"]

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_MASK = (1 << 64) - 1


def mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser of a uint64 array (wrapping arithmetic)."""
    z = x + _GOLDEN
    z = (z ^ (z >> _S30)) * _M1
    z = (z ^ (z >> _S27)) * _M2
    return z ^ (z >> _S31)


def _scalar_mix(x: int) -> int:
    return int(mix64(np.array([x & _MASK], dtype=np.uint64))[0])


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


def uniforms(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    """Uniform numbers in (0, 1), shape ``(N, channels)``, for ``keys`` and ``counters`` ``(N,)``."""
    k = np.asarray(keys, dtype=np.uint64)[:, None]
    c = np.asarray(counters, dtype=np.uint64)[:, None] * np.uint64(channels) + np.arange(
        channels, dtype=np.uint64
    )
    z = mix64(k ^ mix64(c))
    return ((z >> _S11).astype(np.float64) + 0.5) * (1.0 / 9007199254740992.0)


def box_muller(u: np.ndarray) -> np.ndarray:
    """Standard normals ``(N, 2P)`` from uniforms ``(N, 2P)`` in (0, 1) (Box-Muller)."""
    pairs = u.shape[1] // 2
    r = np.sqrt(-2.0 * np.log(u[:, :pairs]))
    phi = 2.0 * np.pi * u[:, pairs : 2 * pairs]
    return np.concatenate([r * np.cos(phi), r * np.sin(phi)], axis=1)


def normals(keys: np.ndarray, counters: np.ndarray, channels: int) -> np.ndarray:
    """Standard normal numbers, shape ``(N, channels)``, by Box-Muller on :func:`uniforms`."""
    pairs = (channels + 1) // 2
    return box_muller(uniforms(keys, counters, 2 * pairs))[:, :channels]
