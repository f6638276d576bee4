"""Lookups by name in the registries (components, presets, agents): one error style everywhere."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def unknown_name(what: str, name: object, known: Iterable[str], listing: str) -> ValueError:
    """`ValueError("unknown <what> 'x' (did you mean y?); <listing>: a, b, c")`, with the known names sorted."""
    known = sorted(known)
    close = difflib.get_close_matches(str(name), known, n=3)
    hint = f" (did you mean {', '.join(close)}?)" if close else ""
    return ValueError(f"unknown {what} {name!r}{hint}; {listing}: {', '.join(known)}")
