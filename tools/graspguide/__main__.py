"""``python -m graspguide`` is the ``graspguide`` command."""

import sys

from graspguide.cli import main

sys.exit(main())
