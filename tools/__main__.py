"""``python -m tools COMMAND ...``: the ``foresight`` command (:mod:`tools.foresight`)."""

import sys

from tools.foresight import main

sys.exit(main())
