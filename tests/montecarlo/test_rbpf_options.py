"""The Rao–Blackwellised particle filter's XLA options (issue 18: compile time ≤ 5 s)."""

from jaxgrav import xla_options
from jaxgrav.montecarlo.spec import cpu_options_for


def test_paper_d_rbpf_takes_the_elemental_emitters():
    # its predicted readings are one dot (jaxgrav.filters.rbpf): as fast with XLA's
    # elemental emitters, which compile in half the time
    assert cpu_options_for("rbpf") == xla_options.CPU_OPTIONS


def test_voyage_rbpf_keeps_the_fusion_emitters():
    assert cpu_options_for("voyage-rbpf") == xla_options.FUSION_EMITTER_OPTIONS
