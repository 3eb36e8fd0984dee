"""A case-insensitive method registry with aliases (after colour-science's ``*_METHODS``).

A foundation: the response solvers, weightings, samplers, merge estimators and
tone-mapping operators each keep one registry of their methods.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from typing import Generic, TypeVar

T = TypeVar("T")
U = TypeVar("U")


class MethodRegistry(Mapping[str, T], Generic[T]):
    """Map method names (and aliases) to methods (functions, or descriptions of a
    method), ignoring case, ``-`` and ``_``.

    >>> methods = MethodRegistry("weighting", {"Debevec1997": abs},
    ...                          aliases={"triangle": "Debevec1997"})
    >>> methods["TRIANGLE"] is abs
    True
    """

    def __init__(
        self, kind: str, methods: Mapping[str, T], aliases: Mapping[str, str] | None = None
    ) -> None:
        self.kind = kind
        self._methods = dict(methods)
        self._aliases = dict(aliases or {})
        self._lookup = {self._key(name): name for name in self._methods}
        for alias, target in self._aliases.items():
            self._lookup[self._key(alias)] = target

    @staticmethod
    def _key(name: str) -> str:
        return name.lower().replace("-", "").replace("_", "")

    def canonical(self, name: str) -> str:
        """The canonical name of ``name``; raises ``KeyError`` listing the choices."""
        try:
            return self._lookup[self._key(name)]
        except KeyError:
            raise KeyError(
                f"unknown {self.kind} method {name!r}; choose from {', '.join(self.names())}"
            ) from None

    def names(self) -> list[str]:
        """Canonical names followed by aliases, as a user may type them."""
        return [*self._methods, *self._aliases]

    def __getitem__(self, name: str) -> T:
        return self._methods[self.canonical(name)]

    def __iter__(self) -> Iterator[str]:
        return iter(self._methods)

    def __len__(self) -> int:
        return len(self._methods)

    def derive(self, make: Callable[[T], U]) -> MethodRegistry[U]:
        """A registry of ``make(method)`` for every method, under the same names and
        aliases (one list of names for two views of the same methods)."""
        return MethodRegistry(self.kind, {name: make(method)
                                          for name, method in self._methods.items()},
                              aliases=self._aliases)
