"""The link code generator: from link_messages.toml, the wire messages of both ends.

    python3 tools/codegen           # (re)writes every output
    python3 tools/codegen --check   # exit 1 naming the stale outputs

One module per job: schema (load and validate the TOML), emit_cpp (messages.h, core_status.h),
emit_python (link/messages.py), emit_golden (the golden frames, encoded independently),
emit_docs (docs/protocol.md's message reference), emit_avr (the per-frame-only board's subset,
lib/graspguide_cue_device), emit_hands (test/data/retry_hands.h, the native retry test's hands
from test/data/hard_hands.json); __main__ writes or checks them.
"""
