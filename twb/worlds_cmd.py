"""``twb worlds generate``: BARN-like world sets with their difficulty (planners/worlds.py, docs/gymnasium.md)."""

from __future__ import annotations

import json
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from .errors import fail
from .sdk_support import TokenOpt, UrlOpt, sdk_client

__all__ = ["worlds_app"]

worlds_app = typer.Typer(help="Generated world sets: `twb worlds generate --count N --seed S`.", no_args_is_help=True)


class Kind(str, Enum):
    cave = "cave"
    blocks = "blocks"


@worlds_app.command("generate")
def generate(
    count: Annotated[int, typer.Option(help="How many worlds (1 to 10000).")] = 10,
    seed: Annotated[int, typer.Option(help="World i is drawn from seed SEED + i: the same options, the same set.")] = 0,
    kind: Annotated[Kind, typer.Option(help="cave: cellular automaton (BARN); blocks: random rectangles.")] = Kind.cave,
    out: Annotated[Optional[Path], typer.Option(  # noqa: UP045 - typer reads Optional
        help="Directory for the environment files and index.json (default: worlds-KIND-SEED).")] = None,
    test_fraction: Annotated[float, typer.Option(
        help="Share of the worlds marked \"test\" in index.json (held out, as BARN holds out 50 of 300); "
             "the others \"train\". Drawn from SEED.")] = 0.2,
    upload: Annotated[bool, typer.Option(help="Also add every world to the testbed as an environment.")] = False,
    url: UrlOpt = None,
    token: TokenOpt = None,
) -> None:
    """Generate COUNT worlds on a 1.8 m sub-field, each solvable by FMM from plan A's start to its goal, with
    BARN's difficulty metrics; write them as environment files plus index.json (name, file, seed, kind,
    parameters, train/test split, metrics, FMM path length), and with --upload add them to the testbed."""
    from planners.worlds import generate_worlds

    if not 1 <= count <= 10_000:
        fail(f"--count must be in [1, 10000], got {count}")
    if seed < 0:
        fail(f"--seed must be >= 0, got {seed}")
    if not 0.0 <= test_fraction <= 1.0:
        fail(f"--test-fraction must be in [0, 1], got {test_fraction}")
    folder = out or Path(f"worlds-{kind.value}-{seed}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"cannot create {folder}: {exc.strerror or exc}")
    worlds = generate_worlds(count, seed, kind=kind.value)
    import numpy as np

    held_out = set(np.random.default_rng(seed).permutation(count)[:round(count * test_fraction)].tolist())
    index = []
    for i, w in enumerate(worlds):
        name = w.environment.name
        (folder / f"{name}.json").write_text(json.dumps(w.environment.to_dict(), indent=1) + "\n")
        length = float(sum(((b - a) ** 2).sum() ** 0.5 for a, b in zip(w.path[:-1, :2], w.path[1:, :2])))
        index.append({"name": name, "file": f"{name}.json", "seed": w.seed, "kind": w.kind, "params": w.params,
                      "attempts": w.attempts, "split": "test" if i in held_out else "train",
                      "fmm_path_length_m": round(length, 4),
                      "difficulty": {k: round(v, 4) for k, v in w.difficulty.to_dict().items()}})
    (folder / "index.json").write_text(json.dumps({"count": count, "seed": seed, "kind": kind.value,
                                                   "worlds": index}, indent=1) + "\n")
    typer.echo(f"{count} {kind.value} worlds in {folder}/ (index.json: their difficulty)")
    if upload:
        with sdk_client(url, token) as client:
            added = sum(client.ensure_environment(w.environment.to_dict())[1] for w in worlds)
        typer.echo(f"added {added} environment(s) to the testbed ({count - added} were there already); "
                   f"use them: twb submit --env {worlds[0].environment.name} --plan A ...")
