"""``python -m markerplace.cli``: the same as the ``markerplace`` command."""

import sys

from .main import main

sys.exit(main())
