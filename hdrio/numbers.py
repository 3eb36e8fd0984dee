"""The one place that checks numbers given by a user (options, operator parameters).

Each check names the option as a user typed it (``--lambda``, ``--tonemap key=``), the
value, and the range it must lie in, and raises :class:`NumberError` (a ``ValueError``
and an :class:`~hdrio.errors.HdrioError`): every front end reports it as bad input.
NaN and infinity are refused everywhere unless a check says otherwise.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from hdrio.errors import HdrioError


class NumberError(HdrioError, ValueError):
    """A number out of its range (the message names the option and the range)."""


def check_number(option: str, value: object, *, minimum: float | None = None,
                 above: float | None = None, maximum: float | None = None,
                 whole: bool = False, hint: str = "") -> float:
    """``value`` as a float (an int when ``whole``), or :class:`NumberError`.

    ``minimum`` is inclusive, ``above`` exclusive; ``hint`` ends the message (what the
    option means, its default).
    """
    tail = f" ({hint})" if hint else ""
    given = f"{option}{value}" if option.endswith("=") else f"{option} {value}"  # key=0.2
    try:
        number = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise NumberError(f"{option} {value!r}: not a number{tail}") from None
    if not math.isfinite(number):
        raise NumberError(f"{given}: must be a finite number{tail}")
    if whole and number != int(number):
        raise NumberError(f"{given}: must be a whole number{tail}")
    if above is not None and not number > above:
        raise NumberError(f"{given}: must be greater than {_shown(above)}{tail}")
    if minimum is not None and number < minimum:
        raise NumberError(f"{given}: must be at least {_shown(minimum)}{tail}")
    if maximum is not None and number > maximum:
        raise NumberError(f"{given}: must be at most {_shown(maximum)}{tail}")
    return int(number) if whole else number


def _shown(limit: float) -> str:
    return str(int(limit)) if float(limit).is_integer() else f"{limit:g}"


# MergeOptions fields that are numbers: the option naming each, and its range.
MERGE_NUMBERS: Mapping[str, tuple[str, dict]] = {
    "smoothing": ("--lambda", {"above": 0.0, "hint": "the response's smoothness weight; "
                               "default 50"}),
    "samples": ("--samples", {"minimum": 1, "whole": True, "hint": "pixels sampled for "
                              "the response solve; default 1000"}),
    "seed": ("--seed", {"minimum": 0, "maximum": 2**31 - 1, "whole": True}),
}


def check_fields(values: object, table: Mapping[str, tuple[str, dict]]) -> None:
    """Check the attributes of ``values`` named in ``table`` (``None`` passes)."""
    for name, (option, limits) in table.items():
        value = getattr(values, name)
        if value is not None:
            check_number(option, value, **limits)


# Operator parameters (``--tonemap NAME key=...``) and the range each must lie in.
TONEMAP_PARAMETERS: Mapping[str, dict[str, float]] = {
    "key": {"above": 0.0},
    "a": {"above": 0.0},
    "white": {"above": 0.0},
    "delta": {"above": 0.0},
    "saturation": {"minimum": 0.0},
    "phi": {"above": 0.0},
    "epsilon": {"above": 0.0},
    "eps": {"above": 0.0},
}


def check_tonemap_parameters(operator: str, parameters: Mapping[str, float]) -> None:
    """Every parameter of a tone-mapping operator finite, and in range where known."""
    for name, value in parameters.items():
        shown = f"{value:g}" if isinstance(value, (int, float)) else value
        check_number(f"{name}=", shown,  # the caller names --tonemap OPERATOR
                     **TONEMAP_PARAMETERS.get(name, {}))
