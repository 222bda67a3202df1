"""``python -m casflex``: the command line, as the ``casflex`` script."""

import sys

from casflex._entry import main

sys.exit(main())
