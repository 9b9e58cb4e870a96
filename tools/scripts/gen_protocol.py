#!/usr/bin/env python3
"""Former entry point of the link code generator, kept for callers not yet switched to
`python3 tools/codegen [--check]`, which it runs."""

import os
import runpy
import sys

if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    sys.argv[0] = "codegen"
    runpy.run_path(os.path.join(os.path.dirname(here), "codegen"), run_name="__main__")
