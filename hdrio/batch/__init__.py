"""A shoot beyond one bracket set: grouping, fingerprints and the journal of finished
sets, the local pool, Dask and sharding: the one place that decides what is done.

Imported in dependency order: grouping (files into sets), fingerprint and journal (what
is done), plan (sets into tasks, shards), partial (stale temporary files), pool (running
a set; the local pool), cluster (Dask, imported on use), shoot (all of it from Python).
``hdrio.batch`` never imports ``hdrio.cli``; the chain's ``--group`` is a thin adapter
over it (:mod:`hdrio.cli.chain_batch`).
"""

from hdrio.batch.fingerprint import set_fingerprint
from hdrio.batch.grouping import (
    BracketSet,
    Frame,
    format_times,
    group_brackets,
    group_frames,
    list_images,
    read_frame,
)
from hdrio.batch.journal import is_done, record_done
from hdrio.batch.partial import clean_partials, stale_partials
from hdrio.batch.pool import SetResult, run_local, run_set
from hdrio.batch.shoot import MergeSet, merge_shoot, run_sets
from hdrio.batch.tasks import DONE, RUN, SetTask, parse_shard, plan_sets, sets_json

__all__ = [
    "DONE", "RUN", "BracketSet", "Frame", "MergeSet", "SetResult", "SetTask",
    "clean_partials", "format_times", "group_brackets", "group_frames", "is_done",
    "list_images", "merge_shoot", "parse_shard", "plan_sets", "read_frame", "record_done",
    "run_local", "run_set", "run_sets", "set_fingerprint", "sets_json", "stale_partials",
]
