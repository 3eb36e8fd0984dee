"""What a pool worker needs before its first set, loaded once by the fork server that
forks the workers (:func:`hdrio.batch.pool.fork_server`): the merge's stages imported,
numba's CPU target loaded (:func:`hdrio.jit.prepare_numba`); the server also imports the
module of the set's work (the chain's, for ``--group``). Each worker forked from the
server has them already; spawned, each paid for them itself. Nothing but a fork server
imports this module."""

from __future__ import annotations

import contextlib
import importlib

from hdrio.jit import prepare_numba

MODULES = ("hdrio.batch.pool", "hdrio.job.run", "hdrio.job.stages",
           "hdrio.align.motion", "hdrio.align.deghost", "hdrio.merge.masked",
           "hdrio.response.debevec1997", "hdrio.tonemap.preview", "hdrio.cms.checks",
           "hdrio.io.half", "scipy.ndimage")
"""What a set of ``--group --merge`` imports (measured: the modules a worker had after its
first set that it did not have at start)."""

for _module in MODULES:
    with contextlib.suppress(ImportError):
        importlib.import_module(_module)
prepare_numba()
