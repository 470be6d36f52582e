"""Optimal mobile-sensor motion for Kalman filtering (SPEC §1): problem, direct and indirect methods.

Importing this package sets ``OPENBLAS_NUM_THREADS=1`` unless the user set it: CasADi's bundled OpenBLAS
otherwise spin-waits in ``sched_yield`` on the tiny dense fronts of MUMPS, which costs CPU and, with one
worker per core (sweeps), time.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
