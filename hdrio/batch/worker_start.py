"""What a pool worker needs before its first set, loaded once by the fork server that
forks the workers (:func:`hdrio.batch.pool.fork_server`): the merge's stages imported,
numba's CPU target loaded (:func:`hdrio.jit.prepare_numba`); the server also imports the
module of the set's work (the chain's, for ``--group``). Each worker forked from the
server has them already; spawned, each paid for them itself. On a first run the kernels
of the merge and of alignment's and deghosting's tests (8-bit RGB brackets, the common
case) are compiled into the disk cache first, once (:func:`hdrio.jit.fill_cache`), where
each worker used to compile them all itself, and the preview's when the chain tone-maps
(:data:`hdrio.jit.FILL_VARIABLE`). A fork server imports this module, and so
can a Dask worker you start yourself: ``dask worker SCHEDULER --preload
hdrio.batch.worker_start`` (docs/farm.md)."""

from __future__ import annotations

import contextlib
import importlib
import os

from hdrio.jit import FILL_VARIABLE, fill_cache, prepare_numba

MODULES = ("hdrio.batch.pool", "hdrio.job.run", "hdrio.job.stages",
           "hdrio.align.motion", "hdrio.align.deghost", "hdrio.merge.masked",
           "hdrio.response.debevec1997", "hdrio.tonemap.preview", "hdrio.cms.checks",
           "hdrio.io.half", "scipy.ndimage")
"""What a set of ``--group --merge`` imports (measured: the modules a worker had after its
first set that it did not have at start)."""

# Nothing here may stop the server: what fails here, a worker meets again (and reports)
# in its set.
for _module in MODULES:
    with contextlib.suppress(Exception):
        importlib.import_module(_module)
prepare_numba()
with contextlib.suppress(Exception):
    fill_cache(extra=[stage for stage in os.environ.get(FILL_VARIABLE, "").split(",")
                      if stage])
