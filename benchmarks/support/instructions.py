"""Instructions a trial and its floors execute, counted by valgrind's callgrind.

On this machine the time of identical code varies between processes by up to 5 %
(``speed.py``: two workers of one tree read 1.007-1.055x), so a time ratio within 5 % of
its target is not resolved by one run. The number of instructions a run executes is the
same from process to process (Drake and the trial are deterministic): it measures the
work each case does (the simulator's and the diagram's, the trial's Python), though not
the time a cache miss costs. Each case runs in a process of its own under
``valgrind --tool=callgrind``, counting only inside ``itertools.starmap`` (which the
worker calls around the counted runs: ``trial_worker.py --count``), 30-60x slower than
natively; two cases run at a time.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from trial_worker import source_tree  # same folder

WORKER = Path(__file__).resolve().parent / "trial_worker.py"
MARKER = "starmap_next"  # CPython's C function that runs itertools.starmap's calls


def check_valgrind() -> None:
    if shutil.which("valgrind") is None:
        raise SystemExit("--instructions: needs valgrind on PATH (Debian: apt install "
                         "valgrind); not found")


def count(kind: str, options: dict, revision: str | None = None, runs: int = 2) -> float:
    """Instructions per run of the worker's ``kind`` (``trial_worker.make_trial``) with
    ``options``, from the tree of git ``revision`` (None: this checkout)."""
    tree = source_tree(revision)
    with tempfile.TemporaryDirectory() as scratch:
        out = Path(scratch) / "callgrind.out"
        env = {**os.environ, "PYTHONPATH": tree, "OPENBLAS_NUM_THREADS": "1"}
        proc = subprocess.run(
            ["valgrind", "--tool=callgrind", "--collect-atstart=no",
             f"--toggle-collect={MARKER}", f"--callgrind-out-file={out}", sys.executable,
             str(WORKER), "--count", kind, json.dumps(options), str(runs)],
            capture_output=True, text=True, env=env, cwd=tree)
        found = re.search(r"Collected\s*:\s*([\d,]+)", proc.stderr)
        if proc.returncode != 0 or "counted" not in proc.stdout or found is None:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"instruction count of {kind} at {revision or 'this tree'} "
                               f"failed (rc {proc.returncode}): {tail}")
    return int(found.group(1).replace(",", "")) / runs


def count_cases(cases: dict, runs: int = 2, jobs: int = 2) -> dict:
    """``{name: instructions per run}`` of ``cases`` (``{name: (kind, options,
    revision)}``), ``jobs`` processes at a time; printed as they finish."""
    check_valgrind()

    def one(item):
        name, (kind, options, revision) = item
        n = count(kind, options, revision, runs)
        print(f"{name:48s} {n / 1e9:8.4f} G instructions per run", flush=True)
        return name, n

    with ThreadPoolExecutor(jobs) as pool:
        return dict(pool.map(one, cases.items()))


def ratio_table(counts: dict, floors: dict) -> list[dict]:
    """Rows: each case's instructions and its ratio to each floor (``{label: name}``)."""
    rows = []
    for name, n in counts.items():
        row = {"case": name, "G_instructions_per_run": round(n / 1e9, 4)}
        for label, floor in floors.items():
            row[f"ratio_to_{label}"] = round(n / counts[floor], 4)
        rows.append(row)
        print(f"{name:48s} " + "  ".join(f"x{row[f'ratio_to_{k}']:.4f} of {k}"
                                          for k in floors), flush=True)
    return rows


def write_section(title: str, args, cases: dict, floors: dict, json_path, runs: int = 2) -> dict:
    """Counts ``cases`` (:func:`count_cases`), tabulates them against ``floors``
    (:func:`ratio_table`) and writes the rows to ``json_path`` and to the benchmark's page,
    in a section of their own (``ResultsRun(..., section="instructions")``); returns the
    data written."""
    from handle_drake.base.results import ResultsRun

    run = ResultsRun(title, args, section="instructions", published={})  # counts: no budget
    rows = ratio_table(count_cases(cases, runs), floors)
    data = {"runs_counted": runs, "table": rows, "load_end": os.getloadavg()[0]}
    run.finish(rows, data, json_path)
    return data
