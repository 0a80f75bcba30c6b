"""``python -m peghole_mjx.cli``: the ``peghole`` command."""

import sys

from peghole_mjx.cli.main import console

sys.exit(console())
