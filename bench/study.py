"""The paper's full study (48 runs) with `twb study paper --embedded` at maximum time scale.

Times the whole command — testbed start-up, planning, 24 simulated and 24
field runs, collection, figures, report and stop — and prints JSON: wall
seconds, runs, runs per minute, and the phases from the command's own output.
As a same-run baseline it also times `twb --help` (interpreter and CLI
start-up), so machines of different speed can be compared by the ratio.

    python bench/study.py [--keep DIR] [--planners fmm,fm2]

``--planners`` runs the paper study with only those planners (a study file of the paper's with its
``planners`` list cut down: e.g. the deterministic planners alone, 32 runs).
"""

from __future__ import annotations

import argparse
import csv
import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import report  # noqa: E402

TWB = [sys.executable, "-m", "twb"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--keep", type=Path, help="write the study here and keep it (default: a temporary directory)")
    ap.add_argument("--sim-robots", type=int, default=4)
    ap.add_argument("--planners", help="comma-separated: the paper study with only these planners")
    args = ap.parse_args()
    out = args.keep or Path(tempfile.mkdtemp(prefix="twb-study-bench-"))
    study = "paper"
    if args.planners:
        from client_sdk.study import paper_spec

        spec = paper_spec().to_json()
        spec["planners"] = [p for p in spec["planners"] if (p if isinstance(p, str) else p["name"])
                            in args.planners.split(",")]
        spec_file = Path(tempfile.mkdtemp(prefix="twb-study-spec-")) / "paper-part.json"
        spec_file.write_text(json.dumps(spec))
        study = str(spec_file)
    t0 = time.perf_counter()
    subprocess.run([*TWB, "--help"], capture_output=True, check=True)
    startup = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = subprocess.run([*TWB, "study", study, "--embedded", "--out", str(out), "--no-progress",
                        "--sim-robots", str(args.sim_robots), "--ompl", str(out / "study.db")],
                       capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        sys.exit(f"twb study failed ({r.returncode}): {r.stderr.strip()}")
    with open(out / "runs.csv") as f:
        rows = list(csv.DictReader(f))
    meta = json.loads((out / "study.json").read_text())
    completed = sum(row["status"] == "completed" for row in rows)
    m = re.search(r"in ([\d.]+) s", r.stdout)
    result = {
        "name": "paper study, embedded, time scale max" + (f", planners {args.planners}" if args.planners else ""),
        "wall_s": round(wall, 2),
        "collect_s": meta.get("wall_s"),
        "startup_report_stop_s": round(wall - (meta.get("wall_s") or 0), 2),
        "command_reported_s": float(m.group(1)) if m else None,
        "runs": len(rows),
        "completed": completed,
        "runs_per_minute": round(len(rows) / wall * 60, 1),
        "sim_robots": args.sim_robots,
        "baseline_twb_help_s": round(startup, 3),
        "ratio_to_baseline": round(wall / startup, 1),
        "target_s": 60,
    }
    report("study", [result])
    if args.keep is None:
        shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
