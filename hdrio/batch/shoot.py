"""A whole shoot from Python: group, plan, clean up, run (locally or on Dask).

>>> from hdrio.batch import MergeSet, merge_shoot        # doctest: +SKIP
>>> from distributed import Client                       # doctest: +SKIP
>>> results = merge_shoot("shoot/", "hdr/{first_stem}.exr", work=MergeSet(),
...                       client=Client("tcp://scheduler:8786"))  # doctest: +SKIP
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hdrio.batch.grouping import DEFAULT_MAX_GAP_S, group_brackets, list_images
from hdrio.batch.partial import clean_partials
from hdrio.batch.pool import OnResult, SetResult, Work, run_local
from hdrio.batch.tasks import RUN, SetTask, plan_sets
from hdrio.errors import HdrioError
from hdrio.job.options import MergeOptions


def run_sets(tasks: Sequence[SetTask], work: Work, *, client: Any = None,
             workers: int | None = None, on_result: OnResult | None = None,
             fill: Sequence[str] = ()) -> list[SetResult]:
    """Run the tasks whose status is ``run``: first remove the stale temporary files of
    killed writers in their output folders (:mod:`hdrio.batch.partial`) and make the
    folders, then run on ``client``'s Dask cluster when given, else in a local pool of
    ``workers`` processes (default: one per CPU)."""
    from hdrio.parallel import threads

    clean_partials({path.parent for task in tasks for path in task.outputs})
    todo = [task for task in tasks if task.status == RUN]
    for path in {path.parent for task in todo for path in task.outputs}:
        path.mkdir(parents=True, exist_ok=True)
    if client is not None:
        from hdrio.batch.cluster import run_dask

        return run_dask(todo, work, client, on_result)
    return run_local(todo, work, workers or threads(), on_result, fill)


@dataclass(frozen=True)
class MergeSet:
    """Work for :func:`run_sets`: :func:`hdrio.job.run.merge_files` of the set to its
    first output, and a tone-mapped preview to the second when there is one."""

    options: MergeOptions = field(default_factory=MergeOptions)
    tonemap: str = "reinhard-global"
    pixel_type: str = "half"

    def recipe(self) -> list[str]:
        """Every setting, as text, for the fingerprint."""
        return [repr(self)]

    def __call__(self, task: SetTask) -> tuple[bool, str]:
        from hdrio.job.run import merge_files

        preview = task.outputs[1] if len(task.outputs) > 1 else None
        try:
            merge_files(task.files, task.outputs[0], preview=preview, tonemap=self.tonemap,
                        options=self.options, pixel_type=self.pixel_type)
        except HdrioError as error:
            return False, f"error: {error}\n"
        return True, "".join(f"wrote {path}\n" for path in task.outputs)


def merge_shoot(inputs: str | Path | Sequence[str | Path], output: str,
                preview: str | None = None, *, work: MergeSet | None = None,
                client: Any = None, workers: int | None = None, force: bool = False,
                shard: tuple[int, int] | None = None, size: int | None = None,
                max_gap_s: float = DEFAULT_MAX_GAP_S, dry_run: bool = False,
                on_result: OnResult | None = None) -> tuple[list[SetTask], list[SetResult]]:
    """Merge every bracket set of a shoot; sets already done are skipped.

    Parameters
    ----------
    inputs : folder or list of files
    output, preview : str
        Patterns of each set's EXR and preview (``{first_stem}``, ``{index}``, ...).
    work : MergeSet
        The merge settings (they are part of each set's fingerprint).
    client : distributed.Client, optional
        Run on its Dask cluster; else in a local process pool of ``workers``.
    force, shard, size, max_gap_s :
        As ``--force``, ``--shard K/N``, ``--group-size``, the gap that splits sets (s).
    dry_run : bool
        Plan only.

    Returns
    -------
    (tasks, results)
        The plan (every set, with its status) and what became of the sets that ran.
    """
    work = work or MergeSet()
    paths = (list_images(inputs) if isinstance(inputs, str | Path) and Path(inputs).is_dir()
             else [Path(p) for p in ([inputs] if isinstance(inputs, str | Path) else inputs)])
    patterns = [output] + ([preview] if preview else [])

    def outputs_for(fields: dict[str, str]) -> list[Path]:
        return [Path(pattern.format(**fields)) for pattern in patterns]

    tasks = plan_sets(group_brackets(paths, max_gap_s, size), outputs_for,
                      [*work.recipe(), *patterns], size=size, force=force, shard=shard)
    if dry_run:
        return tasks, []
    return tasks, run_sets(tasks, work, client=client, workers=workers, on_result=on_result)
