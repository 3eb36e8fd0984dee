"""From bracket sets to tasks: outputs, fingerprints, what is done, shards, the listing.

The order of the sets is the grouping's (capture order), which depends only on the files:
so ``--shard K/N`` gives every farm task the same answer about which sets are its own,
whatever the others have finished.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from hdrio.batch.fingerprint import set_fingerprint
from hdrio.batch.grouping import BracketSet, format_times
from hdrio.batch.journal import is_done
from hdrio.errors import OutputError

RUN, DONE = "run", "done"


@dataclass(frozen=True)
class SetTask:
    """One bracket set as a unit of work.

    Attributes
    ----------
    index : int
        Position of the set in the whole shoot, from 1 (the same in every shard).
    files : tuple of Path
        The frames, in capture order.
    times_s : tuple of float or None
        Their real exposure times in seconds.
    fields : dict
        Names for output patterns (:meth:`BracketSet.fields`).
    outputs : tuple of Path
        The files the set writes.
    fingerprint : str
        :func:`hdrio.batch.fingerprint.set_fingerprint` of the set.
    status : str
        ``run``; ``done`` (recorded with this fingerprint: skipped); or ``skip: why``.
    """

    index: int
    files: tuple[Path, ...]
    times_s: tuple[float | None, ...]
    fields: dict[str, str] = field(hash=False)
    outputs: tuple[Path, ...]
    fingerprint: str
    status: str

    def describe(self) -> str:
        """``7 frames, 1/1000 1/250 ... 1/4 s: IMG_0001.jpg .. IMG_0007.jpg``."""
        count = len(self.files)
        return (f"{count} frame{'' if count == 1 else 's'}, {format_times(self.times_s)}: "
                f"{self.files[0].name} .. {self.files[-1].name}")


def parse_shard(text: str) -> tuple[int, int]:
    """``"K/N"`` into ``(K, N)`` with ``1 <= K <= N``; ``ValueError`` saying why not."""
    try:
        k, n = (int(part) for part in text.split("/"))
    except ValueError:
        raise ValueError(f"expected K/N (the K-th of N parts, e.g. 3/10), got {text!r}"
                         ) from None
    if not 1 <= k <= n:
        raise ValueError(f"K must be 1 .. N in K/N, got {text!r}")
    return k, n


def shard_slice(count: int, k: int, n: int) -> range:
    """Positions ``0 .. count-1`` of the K-th of N contiguous parts whose sizes differ
    by at most one; over K = 1 .. N they cover every position exactly once."""
    return range(count * (k - 1) // n, count * k // n)


def plan_sets(sets: Sequence[BracketSet], outputs_for: Callable[[dict[str, str]], list[Path]],
              recipe: Iterable[str], named_files: Iterable[str | Path] = (), *,
              size: int | None = None, force: bool = False,
              shard: tuple[int, int] | None = None) -> list[SetTask]:
    """A :class:`SetTask` for each set, with what is to be done about it.

    Parameters
    ----------
    sets : sequence of BracketSet
        From :func:`hdrio.batch.grouping.group_brackets`.
    outputs_for : callable
        ``outputs_for(fields) -> [Path, ...]``: the outputs of a set given its fields.
    recipe, named_files :
        The settings part of the fingerprint (:func:`set_fingerprint`).
    size : int, optional
        The expected frames per set (``--group-size``): sets of another count are skipped.
    force : bool
        Run every set, done or not.
    shard : (K, N), optional
        Keep only the K-th of N parts of the sets that can be merged; sets that cannot
        are reported in part 1 only.
    """
    recipe, named_files = list(recipe), list(named_files)
    tasks = []
    for index, bracket_set in enumerate(sets, start=1):
        if len(bracket_set.frames) < 2:
            status = "skip: a single frame is not a bracket set"
        elif size is not None and len(bracket_set.frames) != size:
            status = f"skip: {len(bracket_set.frames)} frames, --group-size is {size}"
        else:
            status = RUN
        fields = bracket_set.fields(index)
        tasks.append(SetTask(index, tuple(bracket_set.files), tuple(bracket_set.times_s),
                             fields, tuple(outputs_for(fields)),
                             set_fingerprint(bracket_set.files, recipe, named_files), status))
    refuse_colliding_outputs(tasks)  # every set's, whichever shard runs it
    if shard is not None:
        runnable = [task for task in tasks if task.status == RUN]
        mine = {task.index for task in
                (runnable[i] for i in shard_slice(len(runnable), *shard))}
        tasks = [task for task in tasks
                 if task.index in mine or (task.status != RUN and shard[0] == 1)]
    if not force:
        tasks = [_with_status(task, DONE) if task.status == RUN
                 and is_done(task.outputs, task.fingerprint) else task for task in tasks]
    return tasks


def refuse_colliding_outputs(tasks: Sequence[SetTask]) -> None:
    """Raise :class:`~hdrio.errors.OutputError` when two outputs of the sets that would
    run are one file (two sets, or two outputs of one set), naming the file and both.

    Otherwise the later would overwrite the earlier, and a rerun would take the earlier
    set's outputs for the later's and merge the earlier again (a fixed ``-o`` name for
    a shoot, or a field such as ``{folder}`` that two sets share)."""
    from hdrio.io.paths import file_key

    written: dict[object, tuple[Path, SetTask]] = {}
    for task in tasks:
        if task.status != RUN:
            continue
        for output in task.outputs:
            earlier = written.setdefault(file_key(output), (output, task))
            if earlier[1] is task and earlier[0] is output:
                continue
            owner = earlier[1]
            if owner is task:
                raise OutputError(f"{output}: set {task.index} ({task.describe()}) would "
                                  "write it twice; give each output its own name")
            example = output.with_name(f"{output.stem}_{{index}}{output.suffix}")
            raise OutputError(
                f"{output}: sets {owner.index} ({owner.describe()}) and {task.index} "
                f"({task.describe()}) would both write it; put {{index}} or "
                f"{{first_stem}} in the output name (e.g. {example})")


def _with_status(task: SetTask, status: str) -> SetTask:
    return SetTask(task.index, task.files, task.times_s, task.fields, task.outputs,
                   task.fingerprint, status)


def sets_json(tasks: Sequence[SetTask]) -> str:
    """The plan as JSON, for tools that plan farm jobs (``--list-sets``).

    A list of objects: ``index`` (from 1), ``status`` (``run``, ``done``, ``skip: ...``),
    ``files``, ``exposure_times_s``, ``outputs``, ``fingerprint``.
    """
    return json.dumps([{"index": task.index, "status": task.status,
                        "files": [str(p) for p in task.files],
                        "exposure_times_s": list(task.times_s),
                        "outputs": [str(p) for p in task.outputs],
                        "fingerprint": task.fingerprint} for task in tasks], indent=1)
