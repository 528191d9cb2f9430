"""The `instrument` command line: one module per subcommand, wired up in `main`."""

import os

# Realtime work wants no BLAS thread pools spinning beside the clock (and the small solves here
# are faster on one thread). Set before numpy is imported; a user's own setting wins.
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")
