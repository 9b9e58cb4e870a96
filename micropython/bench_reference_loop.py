# A float loop whose time on MicroPython boards is published, run here to turn this
# machine's interpreter timings into estimates for a board (docs/micropython.md):
# the Leibniz series for pi, 1,000,000 terms, an int sign and a float sum.
#   micropython micropython/bench_reference_loop.py
import time


def leibniz(terms):
    sign = 1
    total = 1
    for i in range(2, terms + 2):
        sign = sign * -1
        total = total + sign / (2 * i - 1)
    return total * 4


def main():
    best = None
    for _ in range(5):
        t0 = time.ticks_us()
        leibniz(1000000)
        dt = time.ticks_diff(time.ticks_us(), t0)
        best = dt if best is None or dt < best else best
    print("leibniz 1,000,000 terms: best of 5 = %.3f s" % (best / 1e6))


main()
