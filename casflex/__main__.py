"""``python -m casflex``: the command line, as the ``casflex`` script."""

import sys

from casflex.cli import main

sys.exit(main())
