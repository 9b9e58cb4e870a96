#!/usr/bin/env bash
# The habits the test command enforces, one check per argument (tools/run-tests.sh runs
# each as a test case; .pre-commit-config.yaml runs the same ones before a commit):
#   ruff-lint      ruff check (ruff.toml): pycodestyle, pyflakes, isort, bugbear, pyupgrade
#   ruff-format    ruff format --check: the Python is formatted
#   mypy           mypy (mypy.ini): the core and link packages type-check, zero errors
#   clang-format   clang-format --dry-run -Werror (.clang-format) on every hand-written
#                  C/C++ file; the generated ones (.gitattributes) are their generators'
#   generated      every generator's --check: the checked-in outputs are up to date
#   import-layers  lint-imports (.importlinter): the host package's rooms import only the
#                  rooms below them, core imports no other room, and nothing imports in a
#                  circle; it reads the source tree under tools/, not the installed copy
#   all            all of the above
# With --fix, ruff-lint, ruff-format and clang-format rewrite the files instead.
# Needs the .venv of tools/bootstrap.sh (ruff, mypy and clang-format are pinned there).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
BIN="$ROOT/.venv/bin"
FIX=0
if [[ ${1:-} == --fix ]]; then
    FIX=1
    shift
fi

# Tracked C/C++ sources that are not marked linguist-generated in .gitattributes.
hand_written_cpp() {
    git ls-files -- '*.c' '*.cpp' '*.h' '*.ino' |
        git check-attr --stdin linguist-generated |
        awk -F': ' '$3 != "true" { print $1 }'
}

check() {
    case $1 in
        ruff-lint)
            if ((FIX)); then "$BIN/ruff" check --fix .; else "$BIN/ruff" check .; fi
            ;;
        ruff-format)
            if ((FIX)); then "$BIN/ruff" format .; else "$BIN/ruff" format --check .; fi
            ;;
        mypy)
            "$BIN/mypy"
            ;;
        clang-format)
            local files
            mapfile -t files < <(hand_written_cpp)
            if ((FIX)); then
                "$BIN/clang-format" -i "${files[@]}"
            else
                "$BIN/clang-format" --dry-run -Werror "${files[@]}"
                echo "clang-format: ${#files[@]} files formatted"
            fi
            ;;
        import-layers)
            PYTHONPATH="$ROOT/tools" "$BIN/lint-imports" --config "$ROOT/.importlinter"
            ;;
        generated)
            "$BIN/python" tools/codegen --check
            "$BIN/python" tools/scripts/gen_stage_scenes.py --check
            "$BIN/python" tools/scripts/gen_known_answers.py --check
            ;;
        all)
            local c rc=0
            for c in ruff-lint ruff-format mypy clang-format generated import-layers; do
                echo "== $c"
                check "$c" || rc=1
            done
            return $rc
            ;;
        *)
            echo "check_style.sh: unknown check '$1' (ruff-lint, ruff-format, mypy," \
                "clang-format, generated, import-layers, all)" >&2
            return 2
            ;;
    esac
}

if (($# == 0)); then
    set -- all
fi
for c in "$@"; do
    check "$c"
done
