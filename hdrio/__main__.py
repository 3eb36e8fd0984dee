"""``python -m hdrio``: the ``hdrio`` command (:func:`hdrio.cli.main`)."""

import sys

from hdrio.cli import main

sys.exit(main())
