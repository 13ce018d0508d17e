"""Protocol benchmark: parsing the largest legitimate line, and hostile lines, on the agent's parser.

The legitimate line is the largest path a client may send: ``T,T,P`` with
10,000 points whose numbers have the maximum 32 characters (about 1 MiB).
Baseline, measured in the same run on the same payload: the bare numpy
conversion ``np.array(payload.replace(";", ",").split(","), dtype=float)``
with no checks at all (what the agent did after its regular expression
matched).  ``parse`` is :func:`contract.protocol.parse_command` as the
agent calls it (with the RANGE checks of its 1.8 m area).

Hostile lines (each refused with an ``ERR`` reply; the reply is reported):
40,000 and 60,000 digits (the old number regex took ~35 s and ~75 s), 1 MiB
of digits, 1 MiB of ``1,``, 1 MiB of spaces, the legitimate line with its
last number malformed (``...-1``: found by numpy, explained field by field), or
with a control character at its end, and a 1 MiB ``T,T,A`` secret.

Each figure is the median of ``--runs`` (default 7) interleaved rounds;
``ratio`` = time / baseline.  No targets: the point is that every input
costs about as much as converting a legitimate line, or less.

    python bench/protocol.py [--runs 7]
"""

from __future__ import annotations

import argparse
import os
import random
import sys

if __package__ in (None, ""):  # run as a script: bench/ must not shadow the project's packages
    sys.path[0] = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

import numpy as np  # noqa: E402

from bench._common import interleaved, report  # noqa: E402
from contract.protocol import (  # noqa: E402
    MAX_LINE_BYTES,
    MAX_NUMBER_CHARS,
    MAX_POINTS,
    ProtocolError,
    parse_command,
)

AREA = (1.8, 1.8)


def legit_payload(points: int = MAX_POINTS, seed: int = 0) -> str:
    """``x,y,a;...`` with ``points`` points inside the area, every number 32 characters long."""
    rng = random.Random(seed)

    def num(lo: float, hi: float) -> str:
        return f"{rng.uniform(lo, hi):.30f}"[:MAX_NUMBER_CHARS]

    return ";".join(f"{num(100, 1700)},{num(100, 1700)},{num(-179, 179)}" for _ in range(points))


def hostile_lines(legit: bytes) -> dict[str, bytes]:
    """Named hostile lines (terminator included), each at most :data:`MAX_LINE_BYTES`."""
    room = MAX_LINE_BYTES - 8
    return {
        "digits_40k": b"T,T,P," + b"1" * 40_000 + b"x\n",
        "digits_60k": b"T,T,P," + b"1" * 60_000 + b"\n",
        "digits_1MiB": b"T,T,P," + b"1" * room + b"\n",
        "one_comma_1MiB": b"T,T,P," + b"1," * (room // 2) + b"\n",
        "spaces_1MiB": b"T,T,P,1,1," + b" " * (room - 4) + b"\n",
        "legit_last_field_bad": legit[:-3] + b"-1\n",  # still 32 characters: numpy finds it
        "legit_control_char_at_end": legit[:-2] + b"\x1f\n",
        "secret_1MiB": b"T,T,A," + b"x" * room + b"\n",
    }


def _parse(line: bytes) -> str:
    """The agent's first reply word for ``line``: OK or ``ERR,<code>,<message>`` (shortened)."""
    try:
        parse_command(line, field_size=AREA)
        return "OK"
    except ProtocolError as exc:
        return exc.line()[:90]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    args = ap.parse_args()
    payload = legit_payload()
    legit = f"T,T,P,{payload}\n".encode("ascii")
    assert len(legit) <= MAX_LINE_BYTES
    hostile = hostile_lines(legit)
    tasks = {
        "baseline": lambda: np.array(payload.replace(";", ",").split(","), dtype=float),
        "parse_legit_10000_points": lambda: _parse(legit),
        **{name: (lambda line=line: _parse(line)) for name, line in hostile.items()},
    }
    timed = interleaved(tasks, "baseline", args.runs)
    lines = {"parse_legit_10000_points": legit, **hostile}
    results = [
        {"task": name, **val,
         **({"bytes": len(lines[name]), "reply": _parse(lines[name])} if name in lines else {"bytes": len(payload)})}
        for name, val in timed.items()
    ]
    report("protocol", results, runs=args.runs, legit_bytes=len(legit),
           baseline='np.array(payload.replace(";", ",").split(","), dtype=float)')


if __name__ == "__main__":
    main()
