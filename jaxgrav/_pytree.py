"""One decorator for every configuration and state dataclass that is a JAX pytree.

``@pytree_dataclass`` makes a frozen dataclass and registers it with
``jax.tree_util.register_dataclass``: fields are pytree leaves (arrays, numbers a user
may sweep without recompiling) unless declared with :func:`static_field` (settings
that decide shapes or code paths; changing one recompiles).
"""

import dataclasses

import jax

__all__ = ["pytree_dataclass", "static_field"]


def static_field(default=dataclasses.MISSING):
    """A dataclass field that ``jax.tree_util.register_dataclass`` treats as static metadata.

    Static fields decide shapes or code paths; changing one recompiles.
    """
    return dataclasses.field(default=default, metadata=dict(static=True))


def pytree_dataclass(cls):
    """Frozen dataclass registered as a pytree (data fields = leaves, static fields = meta).

    Parameters
    ----------
    cls : type
        The class body, with fields annotated as for :func:`dataclasses.dataclass`.

    Returns
    -------
    type
        ``cls`` as a frozen dataclass, registered with ``jax.tree_util``.
    """
    return jax.tree_util.register_dataclass(dataclasses.dataclass(frozen=True)(cls))
