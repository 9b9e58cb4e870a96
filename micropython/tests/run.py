"""The port's test runner, run INSIDE MicroPython (there is no pytest there):

    micropython micropython/tests/run.py [-k SUBSTRING] [TESTS_DIR]

Imports every test_*.py of TESTS_DIR (default: this file's folder), calls every callable
named test_* in it (sorted by name), and prints one line per test, then
"N passed, N failed". A test fails by raising anything (an AssertionError usually); a
module that fails to import counts as one failed test. Exits 1 when anything failed or
when no test was found (a discovery that finds nothing must not look like a pass).

The port's root (the folder holding graspguide_mp/) and TESTS_DIR go first on sys.path,
so tests `import graspguide_mp.<module>` and their own helpers by name."""

import gc
import os
import sys
import time


def _parent(path):
    i = path.rfind("/")
    if i < 0:
        return "."
    return path[:i] if i > 0 else "/"


def _parse(argv):
    pattern = ""
    folder = None
    i = 0
    while i < len(argv):
        a = argv[i]
        if a == "-k":
            if i + 1 >= len(argv):
                raise ValueError("-k needs a substring of the test names to run")
            pattern = argv[i + 1]
            i += 2
            continue
        if a.startswith("-"):
            raise ValueError("unknown option " + a + "; usage: run.py [-k SUBSTRING] [TESTS_DIR]")
        if folder is not None:
            raise ValueError("give one TESTS_DIR, got " + folder + " and " + a)
        folder = a
        i += 1
    if folder is None:
        folder = _parent(__file__)
    return pattern, folder.rstrip("/") or "/"


def _test_modules(folder):
    names = [n for n in os.listdir(folder) if n.startswith("test_") and n.endswith(".py")]
    names.sort()
    return [n[:-3] for n in names]


def _run_one(label, fn):
    # A board-sized heap: what one test left behind must not fail the next one.
    gc.collect()
    t0 = time.ticks_ms()
    try:
        fn()
    except Exception as e:  # every failure a test can raise is reported
        ms = time.ticks_diff(time.ticks_ms(), t0)
        print("FAIL " + label + " (" + str(ms) + " ms)")
        sys.print_exception(e)
        return False
    ms = time.ticks_diff(time.ticks_ms(), t0)
    print("PASS " + label + " (" + str(ms) + " ms)")
    return True


def main(argv):
    try:
        pattern, folder = _parse(argv)
    except ValueError as e:
        print("run.py: " + str(e))
        return 2
    for p in (_parent(folder), folder):
        if p not in sys.path:
            sys.path.insert(0, p)
    passed = failed = 0
    for mod_name in _test_modules(folder):
        try:
            module = __import__(mod_name)
        except Exception as e:  # an import error is a failed test, not a crash
            print("FAIL " + mod_name + ".py (import)")
            sys.print_exception(e)
            failed += 1
            continue
        for name in sorted(dir(module)):
            fn = getattr(module, name)
            label = mod_name + "." + name
            if not name.startswith("test_") or not callable(fn) or pattern not in label:
                continue
            if _run_one(label, fn):
                passed += 1
            else:
                failed += 1
        # Unloaded, so the next module's tests get the heap its data held.
        del sys.modules[mod_name]
        module = fn = None
    print(str(passed) + " passed, " + str(failed) + " failed")
    if passed + failed == 0:
        print("run.py: no test found in " + folder + " (test_*.py files with test_* functions)")
        return 1
    return 1 if failed else 0


sys.exit(main(sys.argv[1:]))
