"""The ``jaxgrav`` command: one module per sub-command family.

:func:`main` and :func:`build_parser` (:mod:`~jaxgrav.cli.main`) wire the sub-commands
of :mod:`~jaxgrav.cli.match` (``match``, ``simulate``, ``sample``),
:mod:`~jaxgrav.cli.filter`, :mod:`~jaxgrav.cli.simulate_filter`,
:mod:`~jaxgrav.cli.navigate`, :mod:`~jaxgrav.cli.voyage`, :mod:`~jaxgrav.cli.montecarlo`,
:mod:`~jaxgrav.cli.bench`, :mod:`~jaxgrav.cli.dov` and :mod:`~jaxgrav.cli.demo`.
"""

from jaxgrav.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
