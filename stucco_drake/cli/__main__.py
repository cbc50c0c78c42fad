"""``python -m stucco_drake.cli``: the ``stucco-drake`` command."""

import sys

from stucco_drake.cli import main

if __name__ == "__main__":
    sys.exit(main())
