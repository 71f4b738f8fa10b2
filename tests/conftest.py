"""Test configuration: the suite runs in float64 (DESIGN.md, Precision)."""

import jax

jax.config.update("jax_enable_x64", True)
