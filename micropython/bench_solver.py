"""Per-posture solve time and RAM of the port, on the interpreter that runs it:

    micropython bench_solver.py            # bytecode
    micropython bench_solver.py --native   # every function of solver/qp/linalg compiled
                                           # with @micropython.native (a patched copy
                                           # under /tmp, unix port only)

Prints, per k and constraint model, the median of many solves in microseconds
(time.ticks_us) and the bytes allocated by one solve (gc.mem_alloc() delta, gc off)."""

import gc
import sys
import time

REPEATS = 200
MODULES = ("linalg", "qp", "solver", "status")
HAND3 = [[0.045, 0.045, 0.035], [0.015, 0.095, 0.040], [-0.010, 0.100, 0.040]]
HAND4 = HAND3 + [[0.0, 0.045, 0.0]]
WRENCHES = (
    [0.3, -1.2, -0.8, 0.0, 0.0, 0.0],
    [1.0, 0.5, -0.2, 0.0, 0.02, 0.0],
    [-0.4, 0.1, 1.0, 0.01, -0.01, 0.005],
    [0.0, 0.0, -1.0, 0.0, 0.0, 0.0],
)


def _here():
    return __file__.rsplit("/", 1)[0] if "/" in __file__ else "."


def _native_copy(dest):
    """graspguide_mp with @micropython.native on every def, under dest."""
    import os

    for d in (dest, dest + "/graspguide_mp"):
        try:
            os.mkdir(d)
        except OSError:
            pass
    for name in MODULES:
        with open(_here() + "/graspguide_mp/" + name + ".py") as f:
            lines = f.read().split("\n")
        out = ["import micropython"]
        for line in lines:
            stripped = line.lstrip()
            if stripped.startswith("def "):
                out.append(line[: len(line) - len(stripped)] + "@micropython.native")
            out.append(line)
        with open(dest + "/graspguide_mp/" + name + ".py", "w") as f:
            f.write("\n".join(out))


def _median(xs):
    xs = sorted(xs)
    return xs[len(xs) // 2]


def main():
    native = "--native" in sys.argv
    if native:
        _native_copy("/tmp/graspguide_mp_native")
        sys.path.insert(0, "/tmp/graspguide_mp_native")
    else:
        sys.path.insert(0, _here())
    from graspguide_mp.solver import solve

    print(
        "solve per posture, %s, median of %d per scene x %d wrenches"
        % ("native" if native else "bytecode", REPEATS, len(WRENCHES))
    )
    for contacts in (HAND3, HAND4):
        for model in ("paper", "normal", "none"):
            times = []
            allocs = []
            iterations = 0
            for wrench in WRENCHES:
                res = solve(contacts, wrench, "F", "C", model)
                assert res.status == 0, res.status
                iterations += res.iterations
                for _ in range(REPEATS):
                    t0 = time.ticks_us()
                    solve(contacts, wrench, "F", "C", model)
                    times.append(time.ticks_diff(time.ticks_us(), t0))
                gc.collect()
                gc.disable()
                before = gc.mem_alloc()
                solve(contacts, wrench, "F", "C", model)
                allocs.append(gc.mem_alloc() - before)
                gc.enable()
            print(
                "k=%d %-6s median %5d us  (min %d, max %d)  alloc %d..%d bytes/solve"
                "  QP iterations %d"
                % (
                    len(contacts),
                    model,
                    _median(times),
                    min(times),
                    max(times),
                    min(allocs),
                    max(allocs),
                    iterations,
                )
            )


main()
