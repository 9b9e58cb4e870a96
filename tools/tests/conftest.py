"""Shared setup of the tools tests.

The binding and CLI tests run against the package INSTALLED in the interpreter's
environment (``tools/bootstrap.sh`` installs ./tools into .venv), because only that copy
has the compiled extension ``graspguide._core``. Other test modules put ``tools/`` at the
front of ``sys.path`` to reach the pure-Python reference; importing the installed
package here, first, keeps ``graspguide`` the installed one for the whole session.
"""

from __future__ import annotations

import os
import sys

import pytest

TOOLS_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
REPO_ROOT = os.path.dirname(TOOLS_DIR)
KNOWN_ANSWERS = os.path.join(REPO_ROOT, "test", "data", "known_answers.json")
EXAMPLES = os.path.join(TOOLS_DIR, "examples", "solve_requests.jsonl")

_saved_path = list(sys.path)
sys.path[:] = [p for p in sys.path
               if os.path.abspath(p or os.getcwd()) != TOOLS_DIR]
try:
    import graspguide  # noqa: E402

    try:
        from graspguide import _core  # noqa: E402,F401
    except ImportError as e:  # pragma: no cover - setup problem
        _CORE_ERROR = (f"graspguide._core is not importable ({e}); graspguide comes from "
                       f"{os.path.dirname(graspguide.__file__)}. Run `bash tools/bootstrap.sh` "
                       "and the tests with .venv/bin/python (tools/run-tests.sh does both).")
    else:
        _CORE_ERROR = None
finally:
    sys.path[:] = _saved_path


@pytest.fixture(scope="session")
def core():
    if _CORE_ERROR:
        pytest.fail(_CORE_ERROR)
    from graspguide import _core as module

    return module


def subprocess_env() -> dict:
    """Environment for CLI subprocesses: no PYTHONPATH (it could put tools/, without the
    compiled extension, in front of the installed package)."""
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    env["PYTHONIOENCODING"] = "utf-8"
    return env
