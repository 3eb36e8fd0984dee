"""Kernel source rules that keep a first run's compiling short (:mod:`hdrio.jit`)."""

from __future__ import annotations

import ast
from pathlib import Path

import hdrio

_PACKAGE = Path(hdrio.__file__).parent


def _is_kernel(function: ast.FunctionDef) -> bool:
    return any("jit" in ast.unparse(decorator) for decorator in function.decorator_list)


def slice_copies(source: str) -> list[str]:
    """``out[a:b] = values`` (or ``+=``) inside numba kernels of ``source``: an array, or
    anything but a constant, assigned to a slice (hdrio.jit, "Slice copies")."""
    found = []
    for function in ast.walk(ast.parse(source)):
        if not (isinstance(function, ast.FunctionDef) and _is_kernel(function)):
            continue
        for node in ast.walk(function):
            if isinstance(node, ast.Assign):
                targets, value = node.targets, node.value
            elif isinstance(node, ast.AugAssign):
                targets, value = [node.target], node.value
            else:
                continue
            constant = isinstance(value, ast.Constant) or (
                isinstance(value, ast.UnaryOp) and isinstance(value.operand, ast.Constant))
            for target in targets:
                if (isinstance(target, ast.Subscript) and not constant
                        and any(isinstance(n, ast.Slice) for n in ast.walk(target.slice))):
                    found.append(f"{function.name}: {ast.unparse(node)}")
    return found


def test_the_scan_finds_a_slice_copy_and_passes_a_constant_fill():
    source = ("from numba import njit\n"
              "@njit(cache=True)\n"
              "def k(out, row, n):\n"
              "    out[:] = row\n"
              "    out[1:n] += row[1:n]\n"
              "    out[:] = 0.0\n"
              "    out[0] = row[0]\n"
              "def not_a_kernel(out, row):\n"
              "    out[:] = row\n")
    assert slice_copies(source) == ["k: out[:] = row", "k: out[1:n] += row[1:n]"]


def test_no_kernel_copies_an_array_into_a_slice():
    # Each one compiled numba's shape-mismatch message (f-strings) into its kernel: 4.3 s
    # of a first merge's compiling (hdrio.merge.kernel._remap_row's ``out[:] = row``).
    found = {str(path.relative_to(_PACKAGE)): hits
             for path in sorted(_PACKAGE.rglob("*.py"))
             if (hits := slice_copies(path.read_text(encoding="utf-8")))}
    assert found == {}
