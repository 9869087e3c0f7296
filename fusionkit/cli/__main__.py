"""``python -m fusionkit.cli``: the same as the ``fusionkit`` command."""

import sys

from . import main

sys.exit(main())
