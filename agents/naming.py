"""Lookups by name in the registries (components, presets, agents): one error style everywhere
(`hyperstate.registry`, which this module re-exports for its old importers)."""

from hyperstate.registry import unknown_name

__all__ = ["unknown_name"]
