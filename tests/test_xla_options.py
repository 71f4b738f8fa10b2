"""jaxgrav's XLA compiler options: which platforms get them, that they reach XLA, and that
results do not change."""

import gc

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrav import montecarlo, xla_options
from jaxgrav._linalg import expm, modified_cholesky
from jaxgrav.montecarlo.spec import cpu_options_for


def test_options_on_cpu_only():
    assert xla_options.compiler_options("cpu") == {"xla_backend_optimization_level": 2,
                                                   "xla_cpu_use_fusion_emitters": False}
    assert xla_options.compiler_options("cpu", xla_options.FUSION_EMITTER_OPTIONS) == \
        {"xla_backend_optimization_level": 2}
    assert xla_options.compiler_options("gpu") == {}
    assert xla_options.compiler_options(jax.devices("cpu")[0]) == \
        xla_options.compiler_options("cpu")
    assert xla_options.compiler_options() == \
        xla_options.compiler_options(jax.default_backend())
    assert xla_options.compiler_options("cpu", xla_options.XLA_DEFAULTS) == {}


def _program(a):
    low = jax.vmap(lambda x: modified_cholesky(x)[0])(a)
    return jax.vmap(expm)(low * 0.01)


def test_compiled_with_the_options_equals_xla_defaults():
    a = np.stack([np.eye(13) * (i + 1) + 0.1 for i in range(3)])
    fn = jax.jit(_program)
    np.testing.assert_allclose(xla_options.compiled(fn, a)(a), fn(a), rtol=1e-13)


def _toy(key, scale):
    x = jax.random.normal(key, (13, 13)) * scale
    return {"e": expm(x * 0.01), "c": modified_cholesky(x @ x.T + 13 * jnp.eye(13))[0]}


ARGS = (jnp.float64(1.0),)


def test_runner_options_give_the_same_runs():
    ours = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=ARGS, progress=False)
    xla = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=ARGS, progress=False,
                         cpu_options=xla_options.XLA_DEFAULTS)
    for k in ours:
        np.testing.assert_allclose(ours[k], xla[k], rtol=1e-12, atol=1e-15)
    as_dict = montecarlo.run(_toy, jax.random.key(0), 4, chunk=2, args=ARGS, progress=False,
                             cpu_options=dict(xla_options.CPU_OPTIONS))
    np.testing.assert_array_equal(as_dict["e"], ours["e"])


@pytest.mark.parametrize("bad", [5, "xla_backend_optimization_level", (("optimize", 2),),
                                 (("xla_backend_optimization_level", [2]),),
                                 {1: 2, "xla_a": 3}])
def test_bad_options_are_refused(bad):
    with pytest.raises(ValueError, match="cpu_options"):
        montecarlo.run(_toy, jax.random.key(0), 2, args=ARGS, progress=False, cpu_options=bad)


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the options are for CPU")
def test_the_options_reach_xla():
    """An option XLA does not know fails at compile time: the runner passes them on."""
    with pytest.raises(jax.errors.JaxRuntimeError, match="xla_no_such_option"):
        montecarlo.run(_toy, jax.random.key(0), 2, args=ARGS, progress=False,
                       cpu_options=(("xla_no_such_option", 1),))


def test_methods_choose_their_options():
    assert cpu_options_for("ukf") == xla_options.CPU_OPTIONS
    assert cpu_options_for("voyage-dense") == xla_options.CPU_OPTIONS
    assert cpu_options_for("rbpf") == xla_options.CPU_OPTIONS  # since helper-62's map reading
    # voyage-rbpf: 16 % slower runs of 12 h patrols with the elemental emitters, even
    # since its steps stopped joining positions and means into one array (2026-12-08)
    for kind in ("pmf", "voyage-pmf", "voyage-rbpf"):
        assert cpu_options_for(kind) == xla_options.FUSION_EMITTER_OPTIONS


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the options are for CPU")
def test_an_option_of_ours_that_xla_dropped_is_left_out(monkeypatch):
    """jaxgrav's own option sets keep working on an XLA without one of their options;
    an unknown option a user passes still fails (test_the_options_reach_xla)."""
    gone = ("xla_cpu_no_such_emitters", False)
    mine = (*xla_options.CPU_OPTIONS, gone)
    monkeypatch.setattr(xla_options, "CPU_OPTIONS", mine)
    assert xla_options.compiler_options("cpu", mine) == {"xla_backend_optimization_level": 2,
                                                         "xla_cpu_use_fusion_emitters": False}
    with pytest.raises(jax.errors.JaxRuntimeError, match="No such compile option"):
        jax.jit(lambda v: v).lower(1.0).compile(dict([gone]))
    assert xla_options.compiler_options("cpu", (gone,)) == {gone[0]: False}  # not ours


@pytest.mark.skipif(jax.default_backend() != "cpu", reason="the options are for CPU")
def test_the_command_programs_get_the_options(monkeypatch):
    from jaxgrav import executables

    monkeypatch.setattr(xla_options, "compiler_options", lambda *a, **k: {"xla_no_such_option": 1})
    with pytest.raises(jax.errors.JaxRuntimeError, match="xla_no_such_option"):
        executables.call(jax.jit(lambda x: x * 3.0), jnp.ones(3))


def test_gc_paused_restores_the_collector():
    assert gc.isenabled()
    with xla_options.gc_paused():
        assert not gc.isenabled()
    assert gc.isenabled()
    gc.disable()
    try:
        with xla_options.gc_paused():
            assert not gc.isenabled()
        assert not gc.isenabled()  # off before: left off
    finally:
        gc.enable()
    with pytest.raises(RuntimeError), xla_options.gc_paused():
        raise RuntimeError("inside")
    assert gc.isenabled()
