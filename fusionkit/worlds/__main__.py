"""``python -m fusionkit.worlds [--out maps]``: write the simulation worlds as map_server maps."""

import sys

from ..cli._worlds import main

sys.exit(main())
