import os

# Threaded BLAS on 2 cores makes small solves much slower under load.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("HANDLE_DRAKE_REDUCED", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
