"""Writes or checks every output of the link schema; see codegen/__init__.py."""

from __future__ import annotations

import argparse
import os
import sys
import tomllib
from collections.abc import Sequence

if __package__ in (None, ""):  # run as `python3 tools/codegen`: import as the package
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from codegen import emit_avr, emit_cpp, emit_docs, emit_golden, emit_hands, emit_python  # noqa: E402
from codegen.schema import REGEN, Schema, SchemaError, load_schema  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
LINK_SRC = os.path.join(ROOT, "lib", "graspguide_link", "src", "graspguide_link")
CPP_PATH = os.path.join(LINK_SRC, "messages.h")
CORE_STATUS_PATH = os.path.join(LINK_SRC, "core_status.h")
PY_PATH = os.path.join(ROOT, "tools", "graspguide", "link", "messages.py")
GOLDEN_JSON_PATH = os.path.join(ROOT, "test", "data", "golden_frames.json")
GOLDEN_H_PATH = os.path.join(ROOT, "test", "data", "golden_frames.h")
DOC_PATH = os.path.join(ROOT, "docs", "protocol.md")
HANDS_JSON_PATH = os.path.join(ROOT, *emit_hands.HANDS_SOURCE.split("/"))
RETRY_HANDS_H_PATH = os.path.join(ROOT, "test", "data", "retry_hands.h")
AVR_DIR = os.path.join(ROOT, "lib", "graspguide_cue_device", "src", "graspguide_cue_device")


def outputs(schema: Schema) -> dict[str, str]:
    out = {
        CPP_PATH: emit_cpp.render(schema),
        CORE_STATUS_PATH: emit_cpp.render_core_status(schema),
        PY_PATH: emit_python.render(schema),
        GOLDEN_JSON_PATH: emit_golden.render_json(schema),
        GOLDEN_H_PATH: emit_golden.render_h(schema),
    }
    # docs/ may be absent from a partial copy of the tree (the --check test makes one).
    if os.path.exists(DOC_PATH):
        with open(DOC_PATH, encoding="utf-8") as fh:
            out[DOC_PATH] = emit_docs.render(schema, fh.read())
    # Likewise the per-frame board's library (its manifest says whether the copy has it).
    if os.path.exists(os.path.join(os.path.dirname(os.path.dirname(AVR_DIR)), "library.json")):
        out[os.path.join(AVR_DIR, "link_subset.h")] = emit_avr.render(schema)
    if os.path.exists(HANDS_JSON_PATH):
        with open(HANDS_JSON_PATH, encoding="utf-8") as fh:
            out[RETRY_HANDS_H_PATH] = emit_hands.render_h(fh.read())
    return out


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(
        prog="codegen",
        description="Generate the link message code and the native tests' retry hands.",
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="compare the checked-in outputs with what the schema generates; exit 1 if stale",
    )
    args = ap.parse_args(argv)
    try:
        files = outputs(load_schema())
    except (SchemaError, KeyError, tomllib.TOMLDecodeError) as e:
        print(f"codegen: schema error: {e}", file=sys.stderr)
        return 2
    except emit_hands.HandsError as e:
        print(f"codegen: {e}", file=sys.stderr)
        return 2
    stale = []
    for path, text in files.items():
        try:
            with open(path, encoding="utf-8") as fh:
                current: str | None = fh.read()
        except FileNotFoundError:
            current = None
        if current == text:
            continue
        stale.append(os.path.relpath(path, ROOT))
        if not args.check:
            os.makedirs(os.path.dirname(path), exist_ok=True)
            with open(path, "w", encoding="utf-8", newline="\n") as fh:
                fh.write(text)
    if args.check:
        if stale:
            print(
                f"codegen: STALE (regenerate with `{REGEN}`): " + ", ".join(stale), file=sys.stderr
            )
            return 1
        print(f"codegen: {len(files)} outputs up to date")
        return 0
    written = ": " + ", ".join(stale) if stale else " (all were up to date)"
    print(f"codegen: wrote {len(stale)} of {len(files)} outputs{written}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
