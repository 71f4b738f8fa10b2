"""The precision a filter's state is carried in through :func:`~jaxgrav.filters.run_filter`."""

import jax
import jax.numpy as jnp

__all__ = ["in_update_precision"]


def in_update_precision(filt, state, step, field, dynamics):
    """``state`` cast to the precision one ``filt.update`` returns.

    A state below the default float precision (float32 inputs under x64) is promoted by
    the update (float64 dynamics or geodesy), and a ``lax.scan``'s carry must not change
    type; so the scan starts in the update's precision. A state already in the default
    precision is returned as it is, without tracing the update.

    Parameters
    ----------
    filt : Filter
    state : pytree
        From ``filt.init``.
    step : Step
        One step (no leading axis).
    field, dynamics
        As for ``filt.update``.
    """
    canonical = jnp.result_type(float)
    if not any(jnp.issubdtype(a.dtype, jnp.floating) and a.dtype != canonical
               for a in jax.tree.leaves(state) if hasattr(a, "dtype")):
        return state
    after, _ = jax.eval_shape(lambda st, sp: filt.update(st, sp, field, dynamics), state, step)
    return jax.tree.map(lambda a, b: a.astype(b.dtype), state, after)
