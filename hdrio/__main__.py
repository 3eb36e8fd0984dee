"""``python -m hdrio``: the ``hdrio`` command (:func:`hdrio.cli.run`)."""

from hdrio.cli import run

run()
