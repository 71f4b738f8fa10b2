"""``python -m jaxgrav.cli``: the ``jaxgrav`` command."""

import sys

from jaxgrav.cli.main import main

sys.exit(main())
