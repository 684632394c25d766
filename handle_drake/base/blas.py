"""One BLAS thread per process: the one place the project pins it.

Threaded BLAS on a small machine makes the many small solves of a trial (GP
fits, contact QPs) much slower, and worker processes that each start a BLAS
thread per core oversubscribe it. Light on purpose: importing it loads
neither numpy nor Drake.
"""

import os
import sys

__all__ = ["BLAS_VARIABLES", "pin_blas"]

BLAS_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def pin_blas(force: bool = True) -> None:
    """One BLAS thread for this process and the processes it starts.

    ``force=False`` (the command line) only fills in variables the user has not
    set. ``force=True`` (worker processes) sets them, and since numpy may
    already be loaded, when the variables come too late for its BLAS, also
    limits the loaded BLAS libraries live (``threadpoolctl``).
    """
    for name in BLAS_VARIABLES:
        if force:
            os.environ[name] = "1"
        else:
            os.environ.setdefault(name, "1")
    if force and "numpy" in sys.modules:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
