"""Shared test set-up.

The controller works on 5x5 matrices; a multi-threaded BLAS only adds thread hand-over cost
(and under load, spinning threads slow each call 10-30x). Tests, like the CLI, use one thread.
threadpoolctl only limits libraries already loaded, so numpy and scipy.linalg are imported
first.
"""

import os

import numpy  # noqa: F401
import scipy.linalg  # noqa: F401
from hypothesis import settings
from threadpoolctl import threadpool_limits

threadpool_limits(limits=1)

# Hypothesis: CI runs the same examples every time (derandomized, no example database), so a
# run fails only when the code changed; `HYPOTHESIS_PROFILE=explore pytest` draws new random
# examples to look for failures (and keeps them in .hypothesis/ to replay).
settings.register_profile("ci", derandomize=True, database=None)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))
