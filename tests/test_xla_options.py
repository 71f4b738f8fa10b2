"""jaxgrav's XLA compiler options: which platforms get them, and that results do not change."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import xla_options
from jaxgrav._linalg import expm, modified_cholesky


def test_options_on_cpu_only():
    assert xla_options.compiler_options("cpu") == {"xla_backend_optimization_level": 2}
    assert xla_options.compiler_options("gpu") == {}
    assert xla_options.compiler_options(jax.devices("cpu")[0]) == \
        xla_options.compiler_options("cpu")
    assert xla_options.compiler_options() == \
        xla_options.compiler_options(jax.default_backend())


def _program(a):
    low = jax.vmap(lambda x: modified_cholesky(x)[0])(a)
    return jax.vmap(expm)(low * 0.01)


def test_compiled_with_the_options_equals_xla_defaults():
    a = np.stack([np.eye(13) * (i + 1) + 0.1 for i in range(3)])
    fn = jax.jit(_program)
    ours = xla_options.compiled(fn, a)(a)
    np.testing.assert_allclose(ours, fn(a), rtol=1e-13)


@pytest.mark.parametrize("platform", ["cpu", "gpu"])
def test_options_are_accepted_by_jit(platform):
    opts = xla_options.compiler_options(platform)
    f = jax.jit(lambda x: jnp.sin(x) * 2.0, compiler_options=opts)
    np.testing.assert_allclose(f(jnp.ones(3)), 2.0 * np.sin(1.0))


def _toy(key, scale):
    x = jax.random.normal(key, (13, 13)) * scale
    return {"e": expm(x * 0.01), "c": modified_cholesky(x @ x.T + 13 * jnp.eye(13))[0]}


def test_runner_options_give_the_same_runs_and_bad_options_are_refused():
    from jaxgrav import montecarlo

    args = (jnp.float64(1.0),)
    ours = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=args, progress=False)
    xla = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=args, progress=False,
                         cpu_options=xla_options.XLA_DEFAULTS)
    for k in ours:
        np.testing.assert_allclose(ours[k], xla[k], rtol=1e-12, atol=1e-15)
    as_dict = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=args, progress=False,
                             cpu_options=dict(xla_options.CPU_OPTIONS))
    np.testing.assert_array_equal(as_dict["e"], ours["e"])
    for bad in (5, "xla_backend_optimization_level", (("optimize", 2),)):
        with pytest.raises(ValueError, match="cpu_options"):
            montecarlo.run(_toy, jax.random.key(0), 2, args=args, progress=False,
                           cpu_options=bad)


def test_methods_choose_their_options():
    from jaxgrav.montecarlo.spec import cpu_options_for

    assert cpu_options_for("ukf") == xla_options.CPU_OPTIONS
    assert cpu_options_for("voyage-dense") == xla_options.CPU_OPTIONS
    assert cpu_options_for("rbpf") == cpu_options_for("voyage-rbpf") == xla_options.XLA_DEFAULTS
