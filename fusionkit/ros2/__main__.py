"""``python -m fusionkit.ros2 merge-node|play ...``: the same as ``fusionkit ros2 ...``."""

import sys

from ..cli import main

if __name__ == "__main__":
    sys.exit(main(["ros2", *sys.argv[1:]]))
