"""tools/scripts/issue17_m4f_agreement.py as a module for the tests: issue 17's scenes,
their float64 reference answers and the tolerance band. It is a script, not part of the
package, so it is imported from its folder."""

from __future__ import annotations

import sys
from pathlib import Path

_SCRIPTS = str(Path(__file__).resolve().parents[1] / "scripts")
if _SCRIPTS not in sys.path:
    sys.path.insert(0, _SCRIPTS)

import issue17_m4f_agreement as issue17  # noqa: E402

__all__ = ["issue17"]
