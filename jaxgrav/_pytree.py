"""Helpers for frozen dataclasses registered as JAX pytrees."""

import dataclasses

__all__ = ["static_field"]


def static_field(default=dataclasses.MISSING):
    """A dataclass field that ``jax.tree_util.register_dataclass`` treats as static metadata.

    Static fields decide shapes or code paths; changing one recompiles.
    """
    return dataclasses.field(default=default, metadata=dict(static=True))
