"""One small registry for everything chosen by name: tasks, beliefs, bonuses, presets, benchmark agents.

A `Registry` maps names to entries. A miss says what is registered and suggests close names
(`unknown belief 'varibd' (did you mean varibad?); beliefs: ...`); registering a taken name says who
took it (`belief 'oracle' is already registered (by hyperstate.agents.beliefs.oracle)`).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterator, Mapping
from typing import TypeVar

T = TypeVar("T")


def unknown_name(what: str, name: object, known, listing: str) -> ValueError:
    """`ValueError("unknown <what> 'x' (did you mean y?); <listing>: a, b, c")`, with the known names sorted."""
    known = sorted(known)
    close = difflib.get_close_matches(str(name), known, n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    return ValueError(f"unknown {what} {name!r}{hint}; {listing}: {', '.join(known)}")


def no_params(what: str, params: dict) -> None:
    """For components that take no `params` (`what`: "the 'rnd' bonus"): a clear error if some were given."""
    if params:
        raise ValueError(f"{what} takes no params; got {', '.join(map(repr, params))}")


class Registry(Mapping[str, T]):
    """Name → entry, for one kind of thing (`kind`: "belief"; `listing`: how a miss lists them, "beliefs").
    Read like a mapping (`registry[name]`, `name in registry`, iteration in sorted order); `lookup` is the
    read that explains a miss; entries come and go through `add` and `remove` only."""

    def __init__(self, kind: str, listing: str):
        self.kind, self.listing = kind, listing
        self._entries: dict[str, T] = {}
        self._owners: dict[str, str] = {}

    def check_free(self, name: str) -> None:
        """Raises ValueError if `name` is not a non-empty string or is taken."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"a {self.kind} name must be a non-empty string, got {name!r}")
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is already registered (by {self._owners[name]})")

    def add(self, name: str, entry: T, *, owner: str) -> T:
        """Registers `entry` as `name` (`owner`: the module registering it, named on a clash); returns it."""
        self.check_free(name)
        self._entries[name] = entry
        self._owners[name] = owner
        return entry

    def lookup(self, name: str) -> T:
        """The entry registered as `name`; ValueError with close names on a miss."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise unknown_name(self.kind, name, self._entries, self.listing) from None

    def remove(self, name: str) -> None:
        """Unregisters `name` (for tests and interactive sessions)."""
        self.lookup(name)
        del self._entries[name], self._owners[name]

    def names(self) -> list[str]:
        """The registered names, sorted."""
        return sorted(self._entries)

    def __getitem__(self, name: str) -> T:
        return self._entries[name]

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._entries)
