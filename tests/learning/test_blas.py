"""handle_drake.base.blas: the one place BLAS is pinned to one thread per process."""

import json
import os
import subprocess
import sys

CHECK = """
import json, os, sys
from handle_drake.base.blas import BLAS_VARIABLES, pin_blas
mode = sys.argv[1]
if mode == "late":  # numpy (and its BLAS) loaded first, as in a worker process
    import numpy
pin_blas(force=mode != "cli")
import numpy
from threadpoolctl import threadpool_info
print(json.dumps({"env": {n: os.environ.get(n) for n in BLAS_VARIABLES},
                  "threads": [p["num_threads"] for p in threadpool_info()
                              if p["user_api"] == "blas"]}))
"""


def _run(mode, **env):
    base = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", CHECK, mode], capture_output=True, text=True,
                         check=True, env={**base, **env}, timeout=120).stdout
    return json.loads(out)


def test_workers_get_one_blas_thread_even_when_numpy_is_loaded_first():
    late = _run("late")
    assert late["threads"] and set(late["threads"]) == {1}
    assert set(late["env"].values()) == {"1"}  # and the processes it starts


def test_the_command_line_keeps_what_the_user_set():
    cli = _run("cli", OPENBLAS_NUM_THREADS="2")
    assert cli["env"] == {"OPENBLAS_NUM_THREADS": "2", "OMP_NUM_THREADS": "1",
                          "MKL_NUM_THREADS": "1"}
    assert set(_run("cli")["threads"]) == {1}


COMMAND_LINE = """
import json
import handle_drake.cli as cli
from threadpoolctl import threadpool_info

def probe(parser, argv):  # the sub-command would run here, every area module imported
    print(json.dumps([p["num_threads"] for p in threadpool_info() if p["user_api"] == "blas"]))
    return 0

cli.run_command = probe
cli.main(["demo"])
"""


def test_handle_drake_pins_blas_before_its_area_modules_load_numpy():
    base = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", COMMAND_LINE], capture_output=True, text=True,
                         check=True, env=base, timeout=120).stdout
    threads = json.loads(out)
    assert threads and set(threads) == {1}
