"""``python -m markerplace.cli``: the same as the ``markerplace`` command."""

import sys

from markerplace.cli.main import main

sys.exit(main())
