"""The chain's ``--merge`` and its options: every option of ``hdrio merge``, one table.

Each entry of :data:`hdrio.cli.merge_arguments.MERGE_OPTIONS` becomes a chain operation that
sets up the next ``--merge`` (``hdrio a.jpg b.jpg c.jpg --lambda 10 --merge -o out.exr``),
so both front ends take the same options with the same names and meanings and build the
same :class:`~hdrio.job.options.MergeOptions`. Two entries are spelled differently here:
the merge domain is ``--merge``'s own optional argument, and ``--colorspace`` (an image
operation too) is registered by :mod:`hdrio.cli.chain_colour`.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from hdrio.cli.chain_registry import Chain, ChainError, Image, operation
from hdrio.cli.merge_arguments import MERGE_OPTIONS, Option, merge_method, merge_options, set_value

IN_OTHER_OPERATIONS = frozenset({"--merge", "--colorspace"})
PENDING = "_pending_merge_options"  # validation: options given since the last --merge


def note_pending(chain: Chain, text: str) -> None:
    """Validation: ``text`` (a merge option as typed) waits for a later ``--merge``."""
    chain.settings.setdefault(PENDING, []).append(text)


def _setting(option: Option) -> tuple[Callable[[Chain, Any], None], Callable[[Chain, Any], None]]:
    def run(chain: Chain, value: Any) -> None:
        set_value(chain.settings, option, value)

    def check(chain: Chain, value: Any) -> None:
        run(chain, value)
        if option.scope == "merge":
            note_pending(chain, option.name)

    return run, check


for _option in MERGE_OPTIONS:
    if _option.name in IN_OTHER_OPERATIONS:
        continue
    _run, _check = _setting(_option)
    operation(_option.name, *_option.arguments, help=_option.help,
              example=_option.chain_example(),
              convert=_option.parse, aliases=_option.aliases,
              per_set=_option.scope != "global", check=_check)(_run)


def _merge_settings(chain: Chain, domain: str | None) -> dict[str, Any]:
    settings = {key: value for key, value in chain.settings.items() if key != PENDING}
    if domain is not None:
        settings["merge"] = domain
    return settings


def _check_merge(chain: Chain, domain: str | None) -> None:
    if not chain.brackets:
        raise ChainError("no brackets to merge: give the bracket files before --merge")
    settings = _merge_settings(chain, domain)
    options = merge_options(settings)
    exposures = chain.settings.pop("exposures", None)
    chain.settings.pop("exposures_from", None)
    chain.settings.pop(PENDING, None)
    if exposures is not None and len(exposures) != len(chain.brackets):
        raise ChainError(f"--exposures gives {len(exposures)} times for "
                         f"{len(chain.brackets)} brackets")
    chain.brackets = []
    chain.images.append(Image(np.zeros((1, 1, 3), np.float32),
                              {"hdrio:colorSpace": options.output_space}, "merge"))
    chain.last_merge = True


def _optional_domain(token: str) -> bool:
    try:
        merge_method([token])
    except KeyError:
        return False
    return True


@operation("--merge", optional="METHOD", accepts_optional=_optional_domain,
           convert=lambda values: merge_method(values) if values else None,
           check=_check_merge,
           help="merge the pending brackets into scene-linear radiance (estimator: "
                "inverse-variance, the default, Poisson, log (the tutorial's) or linear), "
                "with the merge options given before it (every option of 'hdrio merge', "
                "same names: --lambda, --weighting, --uncertainty, --colorspace...)",
           example="a.jpg b.jpg c.jpg --lambda 10 --merge log -o out.exr")
def _merge(chain: Chain, domain: str | None) -> None:
    from hdrio.job.output import exr_attributes, merge_alpha, merge_layers, output_pixels
    from hdrio.job.run import merge_paths

    if not chain.brackets:
        raise ChainError("no brackets to merge: give the bracket files before --merge")
    settings = _merge_settings(chain, domain)
    options = merge_options(settings)
    result = merge_paths(chain.brackets, exposures=chain.settings.pop("exposures", None),
                         exposures_from=chain.settings.pop("exposures_from", None),
                         options=options, progress=chain.progress.step,
                         read_progress=chain.progress.bar)
    chain.brackets = []
    chain.last_merge = result
    source = result.stack.exposure_sources[0]
    for line in result.exposures.warnings(source) if result.exposures is not None else ():
        print(f"hdrio: warning: {line}", file=sys.stderr)
    if result.exposures is not None and result.exposures.inferred:
        print(f"hdrio: exposures {result.exposures.line()}", file=sys.stderr)
    chain.images.append(Image(output_pixels(result), exr_attributes(result),
                              f"merge of {result.stack.count} brackets", statistics=result,
                              layers=merge_layers(result), alpha=merge_alpha(result)))
