"""Small fixed-size vector helpers on lists of floats (no numpy on a board)."""

import math


def dot(a, b, n):
    s = 0.0
    for i in range(n):
        s += a[i] * b[i]
    return s


def norm(a, n):
    s = 0.0
    for i in range(n):
        s += a[i] * a[i]
    return math.sqrt(s)


def stable_norm(a, n):
    """|a| without overflow or underflow of the squares (Eigen's stableNorm role)."""
    m = 0.0
    for i in range(n):
        v = abs(a[i])
        if v > m:
            m = v
    if not m > 0.0:
        return 0.0
    if m == math.inf:
        return math.inf
    s = 0.0
    for i in range(n):
        v = a[i] / m
        s += v * v
    return m * math.sqrt(s)


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def all_finite(a):
    for v in a:
        if not (v - v == 0.0):  # NaN and +-inf give NaN
            return False
    return True


def popcount(x):
    c = 0
    while x:
        c += x & 1
        x >>= 1
    return c
