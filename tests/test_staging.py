"""Codes staged in a temporary file beyond the memory budget: same pixels, same merge."""

from __future__ import annotations

import numpy as np
import pytest

from hdrio.io.brackets import read_brackets
from hdrio.io.staging import codes_buffer, is_staged, release, write_rows
from hdrio.merge.weighted_mean import merge_brackets
from hdrio.response import response_Debevec1997
from hdrio.stack import ExposureStack


def test_buffer_is_in_memory_within_the_budget_and_staged_beyond():
    assert not is_staged(codes_buffer((2, 8, 8, 3), np.uint8, budget=384))
    staged = codes_buffer((2, 8, 8, 3), np.uint8, budget=383)
    assert is_staged(staged) and is_staged(staged[1:])


def test_released_pages_keep_their_values():
    # 3 brackets of 40 rows x 4 KB: releasing drops pages from the process, not data.
    staged = codes_buffer((3, 40, 1024, 4), np.uint8, budget=0)
    values = np.random.default_rng(0).integers(0, 256, staged.shape, dtype=np.uint8)
    staged[:] = values
    release(staged, 1)
    release(staged, None, 7, 33)
    release(staged[1:], 0, 3, 5)  # a view: offsets relative to the view
    np.testing.assert_array_equal(staged, values)


def test_rows_written_through_the_file_are_what_the_mapping_reads():
    # 5 brackets of 30 rows x 6 KB: a band of 20 rows is 120 KB, more than one write.
    staged = codes_buffer((5, 30, 2048, 3), np.uint8, budget=0)
    staged[:] = 7
    rows = np.random.default_rng(1).integers(0, 256, (20, 2048, 3), dtype=np.uint8)
    assert write_rows(staged[3], 9, rows)
    assert write_rows(staged[1:][0], 0, rows[:5])  # a view: rows of bracket 1
    expected = np.full(staged.shape, 7, np.uint8)
    expected[3, 9:29] = rows
    expected[1, :5] = rows[:5]
    np.testing.assert_array_equal(staged, expected)
    with pytest.raises(ValueError, match="do not fit"):
        write_rows(staged[0], 25, rows)  # 20 rows from row 25 of 30
    in_memory = np.zeros((2, 30, 2048, 3), np.uint8)
    assert not write_rows(in_memory[0], 0, rows)  # the caller writes it
    assert not in_memory.any()


def test_staged_read_and_merge_match_in_memory(write_brackets, monkeypatch):
    paths = write_brackets(size=(300, 200))
    in_memory = read_brackets(paths)
    monkeypatch.setenv("HDRIO_MEMORY_BUDGET_MB", "0")
    staged = read_brackets(paths)
    assert is_staged(staged.codes) and not is_staged(in_memory.codes)
    np.testing.assert_array_equal(staged.codes, in_memory.codes)
    response = response_Debevec1997(in_memory)
    np.testing.assert_array_equal(response_Debevec1997(staged).log_inverse,
                                  response.log_inverse)
    # 300 rows: three bands of the staged merge (MERGE_BAND_ROWS = 128), bit for bit.
    expected, stats = merge_brackets(in_memory, response)
    merged, staged_stats = merge_brackets(staged, response)
    np.testing.assert_array_equal(merged, expected)
    assert staged_stats == stats


def test_staged_stack_views_stay_staged():
    staged = codes_buffer((3, 4, 5, 3), np.uint8, budget=0)
    staged[:] = np.arange(3, dtype=np.uint8)[:, None, None, None] * 80
    stack = ExposureStack.from_arrays(staged[1:], [1.0, 2.0])
    assert is_staged(stack.codes)
