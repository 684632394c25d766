import os
import tempfile

from handle_drake.base.blas import pin_blas  # light: loads neither numpy nor Drake

# Threaded BLAS on 2 cores makes small solves much slower under load.
pin_blas(force=False)
os.environ.setdefault("HANDLE_DRAKE_REDUCED", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
# Mesh objects' convex decompositions go to a shared temporary cache, not the user's
# (content-hashed, written atomically: safe across workers and runs).
os.environ.setdefault("HANDLE_DRAKE_CACHE_DIR",
                      os.path.join(tempfile.gettempdir(), "handle_drake_test_cache"))

