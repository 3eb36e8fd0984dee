"""hdrio.numbers: the one check of user-given numbers (the catalogue runs it end to end)."""

from __future__ import annotations

import pytest

from hdrio.errors import HdrioError
from hdrio.job.options import MergeOptions
from hdrio.numbers import NumberError, check_number, check_tonemap_parameters


@pytest.mark.parametrize("value, problem", [
    ("abc", "not a number"), ("nan", "finite"), ("-inf", "finite"), (float("inf"), "finite"),
    ("0", "greater than 0"), ("-1", "greater than 0"), ("1e309", "finite"),
])
def test_refusals_name_the_option_the_value_and_the_range(value, problem):
    with pytest.raises(NumberError, match=problem) as error:
        check_number("--lambda", value, above=0.0)
    assert str(error.value).startswith("--lambda ")
    assert isinstance(error.value, HdrioError) and isinstance(error.value, ValueError)


def test_whole_numbers_and_inclusive_limits():
    assert check_number("--samples", "12", minimum=1, whole=True) == 12
    assert check_number("--seed", 0, minimum=0, whole=True) == 0
    with pytest.raises(NumberError, match="whole number"):
        check_number("--samples", 2.5, minimum=1, whole=True)
    with pytest.raises(NumberError, match="at most 2147483647"):
        check_number("--seed", 2**31, maximum=2**31 - 1, whole=True)


@pytest.mark.parametrize("field, value, option", [("smoothing", 0.0, "--lambda"),
                                                  ("samples", 0, "--samples"),
                                                  ("seed", -1, "--seed")])
def test_merge_options_refuse_numbers_out_of_range(field, value, option):
    with pytest.raises(NumberError, match=option):
        MergeOptions(**{field: value})
    MergeOptions()  # the defaults pass


def test_tonemap_parameters():
    check_tonemap_parameters("reinhard-global", {"key": 0.18, "white": 8.0})
    with pytest.raises(NumberError, match="key="):
        check_tonemap_parameters("reinhard-global", {"key": -1.0})
    with pytest.raises(NumberError, match="finite"):
        check_tonemap_parameters("reinhard-local", {"phi": float("nan")})


@pytest.mark.parametrize("text", ["lots", "nan", "-5"])
def test_memory_budget_from_the_environment_is_checked(monkeypatch, text):
    from hdrio.io.staging import budget_bytes

    monkeypatch.setenv("HDRIO_MEMORY_BUDGET_MB", text)
    with pytest.raises(NumberError, match="HDRIO_MEMORY_BUDGET_MB"):
        budget_bytes()
    monkeypatch.setenv("HDRIO_MEMORY_BUDGET_MB", "1.5")
    assert budget_bytes() == int(1.5 * 2**20)
