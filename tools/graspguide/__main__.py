"""``python -m graspguide`` is the ``graspguide`` command."""

import sys

from .cli import main

sys.exit(main())
