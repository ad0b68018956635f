"""Shared test set-up.

The controller works on 5x5 matrices; a multi-threaded BLAS only adds thread hand-over cost
(and under load, spinning threads slow each call 10-30x). Tests, like the CLI, use one thread.
threadpoolctl only limits libraries already loaded, so numpy and scipy.linalg are imported
first.
"""

import numpy  # noqa: F401
import scipy.linalg  # noqa: F401
from threadpoolctl import threadpool_limits

threadpool_limits(limits=1)
