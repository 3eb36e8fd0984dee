"""``--group``: the rest of the chain on each bracket set, in a process pool; ``--dry-run``.

Sets whose outputs are all complete (see :func:`hdrio.grouping.output_is_complete`) are
skipped, so a second run over the same folder does nothing and says so.
"""

from __future__ import annotations

import io
import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

from hdrio.cli.chain_output import output_path
from hdrio.cli.progress import Progress
from hdrio.cli.registry import FLOAT_SUFFIXES, Chain, ChainError, Step, operation, run_steps
from hdrio.errors import HdrioError


def _set_outputs(steps: list[Step], fields: dict[str, str]) -> list[Path]:
    probe = Chain(fields=fields)
    return [output_path(probe, step.value) for step in steps if step.name == "-o"]


def _plan_sets(chain: Chain, rest: list[Step]) -> list[tuple[int, Any, list[Path], str]]:
    """``(index, set, outputs, status)`` per set; status ``merge`` or why it is skipped."""
    from hdrio.grouping import group_brackets, output_is_complete

    if not chain.brackets:
        raise ChainError("no brackets to group: give a folder or files before --group")
    if "exposures" in chain.settings:
        raise ChainError("--exposures cannot serve several sets; use EXIF (the default) "
                         "or --exposures-from")
    plan = []
    for index, bracket_set in enumerate(group_brackets(chain.brackets), start=1):
        outputs = _set_outputs(rest, bracket_set.fields(index))
        if len(bracket_set.frames) < 2:
            status = "skip: a single frame is not a bracket set"
        elif outputs and all(output_is_complete(o, bracket_set.files) for o in outputs):
            status = "skip: outputs complete"
        else:
            status = "merge"
        plan.append((index, bracket_set, outputs, status))
    return plan


def _describe(bracket_set) -> str:
    from hdrio.cli.commands import _seconds

    times = sorted(f.exposure for f in bracket_set.frames if f.exposure is not None)
    span = f", {_seconds(times[0])} .. {_seconds(times[-1])}" if times else ""
    return (f"{len(bracket_set.frames)} frames{span}: {bracket_set.frames[0].path.name}"
            f" .. {bracket_set.frames[-1].path.name}")


def run_set(steps: list[Step], files: list[Path], fields: dict[str, str],
            settings: dict[str, Any], verbose: bool) -> tuple[bool, str]:
    """Run ``steps`` on one set (in a worker process); ``(ok, what it printed)``.

    Submitted to the pool through ``chain.run_set`` (:func:`hdrio.cli.chain.run_set`,
    which imports every operation first: a spawned worker starts with none).
    """
    out = io.StringIO()
    chain = Chain(out=out, progress=Progress(quiet=not verbose), brackets=list(files),
                  settings=dict(settings), fields=fields, inputs=list(files))
    try:
        run_steps(chain, steps)
    except HdrioError as error:
        return False, out.getvalue() + f"error: {error}\n"
    return True, out.getvalue()


def _check_group(chain: Chain, _values: list[str]) -> None:
    if not chain.brackets:
        raise ChainError("no brackets to group: give a folder or files before --group")
    if "exposures" in chain.settings:
        raise ChainError("--exposures cannot serve several sets; use EXIF (the default) "
                         "or --exposures-from")


@operation("--group", rest=True, check=_check_group,
           help="split the pending brackets into bracket sets (capture time, exposure "
                "pattern, sequence) and run the rest of the chain on each set, in "
                "parallel; sets whose outputs are complete are skipped",
           example="shoot/ --group --merge -o {first_stem}_hdr.exr")
def run_groups(chain: Chain, _values: list[str], rest: list[Step]) -> None:
    """Split the pending brackets into sets and run ``rest`` on each, in parallel."""
    plan = _plan_sets(chain, rest)
    todo = [entry for entry in plan if entry[3] == "merge"]
    chain.say(f"{len(plan)} bracket sets; {len(todo)} to merge, "
              f"{len(plan) - len(todo)} skipped")
    for index, bracket_set, _outputs, status in plan:
        if status != "merge":
            chain.say(f"  set {index}: {_describe(bracket_set)} ({status})")
    if not todo:
        chain.say("nothing to do: every set's outputs are complete")
        return
    workers = min(chain.settings.get("threads") or multiprocessing.cpu_count(), len(todo))
    failed = []
    # spawn: OpenImageIO and numba keep thread pools that a fork would copy mid-flight.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {pool.submit(chain.run_set or run_set, rest, bracket_set.files,
                               bracket_set.fields(index), chain.settings,
                               not chain.progress.quiet): (index, bracket_set)
                   for index, bracket_set, _outputs, _status in todo}
        for done, future in enumerate(as_completed(futures), start=1):
            index, bracket_set = futures[future]
            ok, printed = future.result()
            chain.progress.bar(done, len(todo), f"set {index}")
            chain.say(f"  set {index}: {_describe(bracket_set)} "
                      f"({'merged' if ok else 'FAILED'})")
            for line in printed.strip().splitlines():
                chain.say(f"    {line}")
            if not ok:
                failed.append(index)
    if failed:
        raise ChainError(f"{len(failed)} of {len(todo)} sets failed (sets "
                         f"{', '.join(map(str, sorted(failed)))}); see above")


def print_plan(chain: Chain, steps: list[Step]) -> None:
    """``--dry-run``: the steps, the sets ``--group`` would find, and what would be done."""
    from hdrio.cli.registry import OPERATIONS

    chain.say("plan (dry run, nothing is written):")
    for number, step in enumerate(steps, start=1):
        if step.name == "read":
            kind = ("folder" if step.value.is_dir() else "image"
                    if step.value.suffix.lower() in FLOAT_SUFFIXES else "bracket")
            chain.say(f"  {number}. read {step.value} ({kind})")
            if kind != "image":
                OPERATIONS["read"].run(chain, step.value)
            continue
        chain.say(f"  {number}. {step.text}")
        if step.name == "--group":
            for index, bracket_set, outputs, status in _plan_sets(chain, steps[number:]):
                targets = ", ".join(str(o) for o in outputs) or "no output"
                chain.say(f"     set {index}: {_describe(bracket_set)} -> {targets} "
                          f"({'would merge' if status == 'merge' else status})")
            return
        if step.name == "-o":
            path = Path(step.value)
            chain.say(f"     would write {path}" + (" (exists: would be replaced)"
                                                    if path.exists() else ""))
