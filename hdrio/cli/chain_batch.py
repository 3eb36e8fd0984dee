"""``--group`` and its settings: the chain's front end to :mod:`hdrio.batch`.

Parsing and printing only: grouping, fingerprints, what is done, the local pool, Dask,
shards and the clean-up of killed writers' temporary files are in :mod:`hdrio.batch`.
Here the rest of the chain after ``--group`` becomes the work of each set, and its steps
(all but those that only say how to run) the recipe of each set's fingerprint.
"""

from __future__ import annotations

import contextlib
import io
from functools import partial
from pathlib import Path
from typing import Any

from hdrio.cli.chain_registry import FLOAT_SUFFIXES, Chain, ChainError, Step, operation, run_steps
from hdrio.cli.progress import Progress
from hdrio.errors import HdrioError

# Steps that say how to run, not what to make: not part of a set's fingerprint.
_HOW_TO_RUN = frozenset({"-v", "--threads", "--dry-run", "--group", "--force", "--dask",
                         "--shard", "--list-sets", "--group-size", "--group-gap"})
# Steps that name outputs of a set (pattern fields allowed).
_OUTPUTS = frozenset({"-o", "--plot-response", "--plot-contribution", "--plot-stops",
                      "--contact-sheet"})


def _positive_int(values: list[str]) -> int:
    if not values[0].isdigit() or int(values[0]) < 1:
        raise ValueError(f"expected a positive whole number, got {values[0]!r}")
    return int(values[0])


def _seconds(values: list[str]) -> float:
    try:
        value = float(values[0])
    except ValueError:
        raise ValueError(f"expected seconds, got {values[0]!r}") from None
    if not value >= 0:
        raise ValueError(f"expected seconds >= 0, got {values[0]!r}")
    return value


def _shard(values: list[str]) -> tuple[int, int]:
    from hdrio.batch.tasks import parse_shard

    return parse_shard(values[0])


def _dask_address(values: list[str]) -> str:
    from hdrio.batch.cluster import parse_address

    parse_address(values[0])
    return values[0]


def _setting(key: str):
    def run(chain: Chain, value: Any) -> None:
        chain.settings[key] = True if isinstance(value, list) else value

    return run


def _batch_setting(name: str, *arguments: str, **declaration: Any) -> None:
    """Register ``name`` as a batch setting (the whole run's, not a set's), stored in
    ``chain.settings`` under ``name`` without its dashes (``--group-size``:
    ``group_size``)."""
    operation(name, *arguments, per_set=False, **declaration)(
        _setting(name.removeprefix("--").replace("-", "_")))


_batch_setting("--force", help="with --group: run every set, even those whose outputs are "
               "recorded as made from the same inputs and settings",
               example="shoot/ --group --force --merge -o {first_stem}.exr")
_batch_setting("--group-size", "N", convert=_positive_int,
               help="with --group: every N frames in capture order are one set (a fixed "
                    "bracket count), instead of splitting on time gaps and repeated "
                    "exposures",
               example="shoot/ --group-size 7 --group --merge -o {first_stem}.exr")
_batch_setting("--group-gap", "SECONDS", convert=_seconds,
               help="with --group: a pause longer than this after a frame ends starts a new "
                    "set (default 2)",
               example="shoot/ --group-gap 5 --group --merge -o {index}.exr")
_batch_setting("--shard", "K/N", convert=_shard,
               help="with --group: run only the K-th of N equal, fixed parts of the sets "
                    "(one farm task each; together the N tasks cover every set once)",
               example="shoot/ --shard 3/10 --group --merge -o {first_stem}.exr")
_batch_setting("--list-sets",
               help="with --group: print the sets as JSON (files, exposure times, outputs, "
                    "fingerprint, status run/done/skip) and do nothing else",
               example="shoot/ --list-sets --group --merge -o {first_stem}.exr")
_batch_setting("--dask", "ADDRESS", convert=_dask_address,
               help="with --group: run the sets on a Dask cluster: a scheduler address "
                    "(tcp://host:8786) or local[:N] (N worker processes here); the farm "
                    "extra",
               example="shoot/ --dask local:2 --group --merge -o {first_stem}.exr")


def check_batch_options(steps: list[Step]) -> None:
    """Refuse batch settings without ``--group`` before any work."""
    names = {step.name for step in steps}
    if "--group" in names:
        return
    for step in steps:
        if step.name in _HOW_TO_RUN - {"-v", "--threads", "--dry-run", "--group"}:
            raise ChainError(f"{step.text}: only with --group (a folder or list of "
                             "bracket sets)")


# ------------------------------------------------------------------------------ plan


def _recipe(steps: list[Step]) -> tuple[list[str], list[Path]]:
    """The fingerprint's recipe (the steps' text) and the files the settings name."""
    recipe, named = [], []
    for step in steps:
        if step.name == "read" or step.name in _HOW_TO_RUN:
            continue
        recipe.append(step.text)
        if step.name in _OUTPUTS:
            continue
        values = step.value if isinstance(step.value, list | tuple) else [step.value]
        named += [Path(v) for v in values if isinstance(v, str) and Path(v).is_file()]
    return recipe, named


def _plan(chain: Chain, steps: list[Step], rest: list[Step]):
    """The :class:`hdrio.batch.SetTask` of every set (of this shard)."""
    from hdrio.batch.grouping import DEFAULT_MAX_GAP_S, group_brackets
    from hdrio.batch.tasks import plan_sets
    from hdrio.cli.chain_output import output_path
    from hdrio.io.paths import check_not_an_input

    if not chain.brackets:
        raise ChainError("no brackets to group: give a folder or files before --group")
    if "exposures" in chain.settings:
        raise ChainError("--exposures cannot serve several sets; use EXIF (the default) "
                         "or --exposures-from")
    settings = chain.settings

    def outputs_for(fields: dict[str, str]) -> list[Path]:
        probe = Chain(fields=fields)
        return [output_path(probe, step.value) for step in rest if step.name in _OUTPUTS]

    recipe, named = _recipe(steps)
    sets = group_brackets(chain.brackets, settings.get("group_gap", DEFAULT_MAX_GAP_S),
                          settings.get("group_size"))
    _check_inferable(sets, settings, steps)
    tasks = plan_sets(sets, outputs_for, recipe, named, size=settings.get("group_size"),
                      force=bool(settings.get("force")), shard=settings.get("shard"))
    for task in tasks:  # a pattern naming an input is not a finished output
        for output in task.outputs:
            check_not_an_input(output, task.files)
    return tasks


def _check_inferable(sets, settings: dict[str, Any], steps: list[Step]) -> None:
    """``--exposures-from-data`` on frames with no exposure and no capture time: only
    ``--group-size`` can split them into sets (nothing else marks where a set ends), so
    without it, refuse before any work, naming a frame."""
    inferring = settings.get("exposures_from_data") or any(
        step.name == "--exposures-from-data" for step in steps)
    if not inferring or settings.get("group_size") is not None:
        return
    frames = [frame for bracket_set in sets for frame in bracket_set.frames]
    if len(sets) > 1 or all(frame.captured is not None for frame in frames):
        return
    unknown = next((frame for frame in frames if frame.exposure is None), None)
    if unknown is not None:
        raise ChainError(f"{unknown.path}: no exposure metadata and no capture "
                         "time, so nothing marks where one bracket set ends; give "
                         "--group-size N (N frames in name order per set)")


# ------------------------------------------------------------------------------- run


def run_set(steps: list[Step], settings: dict[str, Any], verbose: bool,
            task) -> tuple[bool, str]:
    """Run ``steps`` on one set (in a worker); ``(ok, what it printed)``.

    Submitted through ``chain.run_set`` (:func:`hdrio.cli.chain.run_set`, which imports
    every operation first: a spawned or Dask worker starts with none registered).
    """
    out = io.StringIO()
    files = list(task.files)
    chain = Chain(out=out, progress=Progress(quiet=not verbose), brackets=list(files),
                  settings=dict(settings), fields=dict(task.fields), inputs=list(files))
    try:
        run_steps(chain, steps)
    except HdrioError as error:
        return False, out.getvalue() + f"error: {error}\n"
    return True, out.getvalue()


def _compiles_first(settings: dict[str, Any], sets: int) -> bool:
    """Whether the workers' fork server compiles kernels before it forks them
    (:mod:`hdrio.batch.worker_start`): a pool of several workers or ``--dask local``,
    forked, on a first run."""
    from hdrio.batch.cluster import LOCAL, parse_address
    from hdrio.batch.pool import forks_workers
    from hdrio.jit import FILLED, is_stage_cached
    from hdrio.parallel import threads

    address = settings.get("dask")
    forked = (parse_address(address)[0] == LOCAL if address
              else min(settings.get("threads") or threads(), sets) > 1)
    return forked and forks_workers() and not all(
        is_stage_cached(stage) for group in FILLED for stage in group)


@contextlib.contextmanager
def _client(address: str, work, fill: tuple[str, ...]):
    """The ``distributed.Client`` of ``--dask``, closed on leaving (and a local cluster
    with it, its workers forked: :func:`hdrio.batch.cluster.forked_workers`)."""
    from hdrio.batch.cluster import LOCAL, forked_workers, local_cluster, parse_address

    try:
        from distributed import Client
    except ImportError:
        raise ChainError("--dask needs Dask: pip install 'hdrio[farm]'") from None
    where, workers = parse_address(address)
    if where == LOCAL:
        with forked_workers(workers, work, fill), local_cluster(workers) as cluster, \
                Client(cluster) as client:
            yield client
        return
    try:
        client = Client(where, timeout=30)
    except OSError as error:
        raise ChainError(f"--dask {address}: cannot reach the scheduler ({error})") from None
    with client:
        yield client


def _check_group(chain: Chain, _values: list[str]) -> None:
    if not chain.brackets:
        raise ChainError("no brackets to group: give a folder or files before --group")
    if "exposures" in chain.settings:
        raise ChainError("--exposures cannot serve several sets; use EXIF (the default) "
                         "or --exposures-from")


@operation("--group", rest=True, check=_check_group,
           help="split the pending brackets into bracket sets (repeated exposures, time "
                "gaps, file-name ladders, --group-size) and run the rest of the chain on "
                "each set, in parallel; a set is done when its outputs were made from the "
                "same inputs and settings (--force redoes it)",
           example="shoot/ --group --merge -o {first_stem}_hdr.exr")
def run_groups(chain: Chain, _values: list[str], rest: list[Step],
               steps: list[Step]) -> None:
    """Split the pending brackets into sets and run ``rest`` on each, in parallel."""
    from hdrio.batch import DONE, RUN, run_sets, sets_json

    tasks = _plan(chain, steps, rest)
    if chain.settings.get("list_sets"):
        print(sets_json(tasks), file=chain.out)
        return
    todo = [task for task in tasks if task.status == RUN]
    done = sum(task.status == DONE for task in tasks)
    chain.say(f"{len(tasks)} bracket sets; {len(todo)} to merge, {done} done, "
              f"{len(tasks) - len(todo) - done} skipped")
    for task in tasks:
        if task.status != RUN:
            why = ("done: outputs recorded with the same inputs and settings"
                   if task.status == DONE else task.status)
            chain.say(f"  set {task.index}: {task.describe()} ({why})")
    if not todo:
        chain.say("nothing to do: every set is done or skipped")
        return
    bar = Progress(quiet=False)  # a bar of sets, on a terminal only

    def report(result, count: int, total: int) -> None:
        task = next(t for t in todo if t.index == result.index)
        bar.bar(count, total, f"set {task.index}")
        chain.say(f"  set {task.index} [{count}/{total}]: {task.describe()} "
                  f"({'merged' if result.ok else 'FAILED'} in {result.seconds:.1f} s, "
                  f"worker peak {result.peak_rss_mb:.0f} MB)")
        for line in result.printed.strip().splitlines():
            chain.say(f"    {line}")

    work = partial(chain.run_set or run_set, rest, chain.settings, not chain.progress.quiet)
    if _compiles_first(chain.settings, len(todo)):
        chain.say("compiling kernels (first run only), once before the workers start; "
                  "later runs load them from the cache")
    # what the workers' fork server compiles on a first run besides the merge's
    fill = tuple(f"preview={step.value[0]}" for step in rest if step.name == "--tonemap")
    with (_client(chain.settings["dask"], work, fill) if chain.settings.get("dask")
          else contextlib.nullcontext()) as client:
        results = run_sets(tasks, work, client=client, workers=chain.settings.get("threads"),
                           on_result=report, fill=fill)
    failed = sorted(result.index for result in results if not result.ok)
    if failed:
        raise ChainError(f"{len(failed)} of {len(todo)} sets failed (sets "
                         f"{', '.join(map(str, failed))}); see above")


def print_plan(chain: Chain, steps: list[Step]) -> None:
    """``--dry-run``: the steps, the sets ``--group`` would find, and what would be done."""
    from hdrio.batch import DONE, RUN, sets_json
    from hdrio.cli.chain_registry import OPERATIONS

    if not chain.settings.get("list_sets"):
        chain.say("plan (dry run, nothing is written):")
    for number, step in enumerate(steps, start=1):
        if step.name == "read":
            kind = ("folder" if step.value.is_dir() else "image"
                    if step.value.suffix.lower() in FLOAT_SUFFIXES else "bracket")
            if not chain.settings.get("list_sets"):
                chain.say(f"  {number}. read {step.value} ({kind})")
            if kind != "image":
                OPERATIONS["read"].run(chain, step.value)
            continue
        if step.name == "--group":
            tasks = _plan(chain, steps, steps[number:])
            if chain.settings.get("list_sets"):
                print(sets_json(tasks), file=chain.out)
                return
            chain.say(f"  {number}. {step.text}")
            for task in tasks:
                targets = ", ".join(str(o) for o in task.outputs) or "no output"
                what = {RUN: "would merge", DONE: "done: would skip"}.get(task.status,
                                                                        task.status)
                chain.say(f"     set {task.index}: {task.describe()} -> {targets} ({what})")
            return
        chain.say(f"  {number}. {step.text}")
        if step.name == "-o":
            path = Path(step.value)
            chain.say(f"     would write {path}" + (" (exists: would be replaced)"
                                                    if path.exists() else ""))
