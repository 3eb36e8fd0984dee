"""Converters of command-line values: ``convert(list_of_argument_strings) -> value``.

Each raises ``ValueError`` (or ``KeyError`` from a method registry) with a message that
the caller prefixes with the option and its arguments; the option table
(:mod:`hdrio.cli.merge_arguments`) and the chain's operations use them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any


def flag(values: list[str]) -> bool:
    """A flag (an option without arguments): ``True`` when given."""
    return True


def text(values: list[str]) -> str:
    return values[0]


def number(values: list[str]) -> float:
    """A finite number (NaN and infinity are refused, as by :mod:`hdrio.numbers`)."""
    try:
        value = float(values[0])
    except ValueError:
        raise ValueError(f"not a number: {values[0]!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"must be a finite number, got {values[0]!r}")
    return value


def positive_number(values: list[str]) -> float:
    value = number(values)
    if not value > 0:
        raise ValueError(f"expected a positive number, got {values[0]!r}")
    return value


def whole(values: list[str]) -> int:
    try:
        return int(values[0])
    except ValueError:
        raise ValueError(f"expected a whole number, got {values[0]!r}") from None


def positive_whole(values: list[str]) -> int:
    value = whole(values)
    if value < 1:
        raise ValueError(f"expected a positive whole number, got {values[0]!r}")
    return value


def integers(count: int, what: str) -> Callable[[list[str]], tuple[int, ...]]:
    def convert(values: list[str]) -> tuple[int, ...]:
        try:
            numbers = tuple(int(v) for v in values[0].split(","))
        except ValueError:
            numbers = ()
        if len(numbers) != count:
            raise ValueError(f"expected {what}")
        return numbers

    return convert


def registry(getter: Callable[[], Any]) -> Callable[[list[str]], str]:
    """A converter to the canonical name in a method registry (``KeyError`` lists them)."""

    def convert(values: list[str]) -> str:
        return getter().canonical(values[0])

    return convert


def choice(*choices: str) -> Callable[[list[str]], str]:
    def convert(values: list[str]) -> str:
        if values[0] not in choices:
            raise ValueError(f"choose from {', '.join(choices)}")
        return values[0]

    return convert


def exposure_list(values: list[str]) -> tuple[str, ...]:
    from hdrio.io.exposure import explicit_exposures, split_exposures

    times = tuple(split_exposures(values[0]))
    explicit_exposures(times)  # a typo fails here, before any image is read
    return times


def white_balance(values: list[str]) -> tuple[float, ...]:
    """``X,Y,W,H`` (a neutral region, four whole numbers) or ``R,G,B`` (RAW multipliers)."""
    parts = values[0].split(",")
    if len(parts) == 4:
        return integers(4, "a region X,Y,W,H")(values)
    try:
        numbers = tuple(float(v) for v in parts)
    except ValueError:
        numbers = ()
    if len(numbers) != 3 or not all(math.isfinite(v) and v > 0 for v in numbers):
        raise ValueError("expected a neutral region X,Y,W,H (whole numbers) or three "
                         "positive camera RAW multipliers R,G,B")
    return numbers


def skip_name(values: list[str]) -> str:
    from hdrio.skips import SKIPS

    if values[0] not in (*SKIPS, "all"):
        raise ValueError(f"choose from {', '.join(SKIPS)}, all")
    return values[0]


def encoding_name(values: list[str]) -> str:
    from hdrio.cms.encoding import encoding

    encoding(values[0])  # raises naming the choices
    return values[0]


def tonemap_arguments(values: list[str]) -> tuple[str, dict[str, float]]:
    """``OPERATOR [NAME=VALUE,...]``: the canonical operator and its parameters, each
    checked against the operator's signature (so ``white=8`` on an operator without a
    ``white`` fails here, not after the merge)."""
    import inspect

    from hdrio.tonemap import TONEMAP_METHODS

    name = TONEMAP_METHODS.canonical(values[0])
    accepted = [p for p in inspect.signature(TONEMAP_METHODS[name]).parameters
                if p not in ("rgb", "hdr", "space")]
    parameters: dict[str, float] = {}
    for item in values[1].split(",") if len(values) > 1 else []:
        key, _, text = item.partition("=")
        key = key.strip()
        if key not in accepted:
            raise ValueError(f"{name} has no parameter {key!r}; it takes "
                             f"{', '.join(accepted)}")
        try:
            parameters[key] = float(text)
        except ValueError:
            raise ValueError(f"parameter {item!r}: expected NAME=NUMBER") from None
    from hdrio.numbers import check_tonemap_parameters

    check_tonemap_parameters(name, parameters)
    return name, parameters


def response_methods():
    from hdrio.response import RESPONSE_METHODS
    return RESPONSE_METHODS


def sampling_methods():
    from hdrio.response import SAMPLING_METHODS
    return SAMPLING_METHODS


def weighting_methods():
    from hdrio.radiometry.weighting import WEIGHTING_METHODS
    return WEIGHTING_METHODS


def merge_methods():
    from hdrio.merge import MERGE_METHODS
    return MERGE_METHODS


merge_method = registry(merge_methods)


def nd_filter(values: list[str]):
    """``--nd STOPS[:PATTERN]`` (:func:`hdrio.merge.nd.parse_nd`)."""
    from hdrio.merge.nd import parse_nd

    return parse_nd(values[0])
