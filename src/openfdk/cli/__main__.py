"""``python -m openfdk.cli ARGS``: the ``openfdk`` command."""

import sys

from .commands import main

sys.exit(main())
