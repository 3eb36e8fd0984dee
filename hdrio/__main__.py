import sys

from hdrio.cli import main

sys.exit(main())
