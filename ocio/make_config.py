"""Write ocio/config.ocio, hdrio's OpenColorIO config (built by hdrio.cms.ocioconfig).

Run from the repository root after changing hdrio/cms/ocioconfig.py:

    python ocio/make_config.py
"""

from __future__ import annotations

import sys
from pathlib import Path

from hdrio.cms.ocioconfig import project_config
from hdrio.io.write import write_text


def main() -> int:
    target = Path(__file__).resolve().parent / "config.ocio"
    write_text(target, project_config().serialize())
    print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
