"""Reading the numbers of OBJ vertex lines (``v x y z``) exactly as the C library's ``strtod`` reads them, compiled.

numpy's text reader (``np.loadtxt``) spends 4-21 ms on each of ICT FaceKit's 58 files (26,719 lines each, by the
machine), two thirds of loading the rig. This reads the same lines in an eighth of that (2.4 ms against 19 ms a
file, measured on one machine), into the same bits:

Clinger 1990 ("How to read floating point numbers accurately", the fast path of section 3): a decimal number
with significand m (its digits as an integer) and exponent e (value m x 10^e) converts exactly when m < 2^53
and |e| <= 22: m and 10^|e| are then both exact doubles, and one IEEE multiplication or division rounds their
product or quotient correctly, which is what ``strtod`` returns. OBJ files written by DCCs (``%g``, ``%f``,
``%.6f``) are inside that path; a number outside it (more than 15 digits, an exponent beyond it) is left for
the caller to convert with Python's ``float`` (correctly rounded too), and anything that is not a plain
decimal line (``nan``, a fourth coordinate, a colour, a stray character) makes the whole block the caller's
(``-1``), so the reader's own checks and messages stay where they were.

Compiled ahead of time with the take solver's kernel (``solvers.take_kernel``), never imported with numba in a
loading process: importing numba costs more than the parse saves.
"""
from __future__ import annotations

try:
    from numba import njit
except ImportError:                         # the caller keeps numpy's reader
    njit = None


def _blank(ch) -> bool:
    return ch == 32 or ch == 9 or ch == 13


def parse_vertex_lines(c, out, slow, n_slow):
    """Parse ``c`` (uint8: lines ``v x y z``, the last one with or without its newline) into ``out`` (V, 3).

    ``slow`` (S, 3) int64 receives (flat index into ``out``, start, end) of each number outside the fast path,
    its count in ``n_slow[0]``. Returns V, or -1 when some line is not a plain ``v`` line of three decimal
    numbers, there are more or fewer lines than ``out`` has rows, or more slow numbers than ``slow`` holds."""
    n = c.shape[0]
    V = out.shape[0]
    i = 0
    row = 0
    n_slow[0] = 0
    while i < n:
        if row >= V or c[i] != 118 or i + 1 >= n or not _blank(c[i + 1]):   # 'v' and a blank
            return -1
        i += 1
        for col in range(3):
            while i < n and _blank(c[i]):
                i += 1
            start = i
            neg = False
            if i < n and (c[i] == 45 or c[i] == 43):     # - +
                neg = c[i] == 45
                i += 1
            m = 0
            digits = 0
            frac = 0
            dot = False
            while i < n:
                ch = c[i]
                if 48 <= ch <= 57:
                    if digits < 18:
                        m = m * 10 + (ch - 48)
                    digits += 1
                    if dot:
                        frac += 1
                elif ch == 46 and not dot:
                    dot = True
                else:
                    break
                i += 1
            if digits == 0:
                return -1
            e = 0
            if i < n and (c[i] == 101 or c[i] == 69):    # e E
                i += 1
                eneg = False
                if i < n and (c[i] == 45 or c[i] == 43):
                    eneg = c[i] == 45
                    i += 1
                ne = 0
                while i < n and 48 <= c[i] <= 57:
                    if ne < 6:
                        e = e * 10 + (c[i] - 48)
                    ne += 1
                    i += 1
                if ne == 0:
                    return -1
                if eneg:
                    e = -e
            if i < n and not (_blank(c[i]) or c[i] == 10):    # a number ends at a blank or the line's end
                return -1
            e -= frac
            if digits > 15 or e < -22 or e > 22:
                k = n_slow[0]
                if k >= slow.shape[0]:
                    return -1
                slow[k, 0] = row * 3 + col
                slow[k, 1] = start
                slow[k, 2] = i
                n_slow[0] = k + 1
                out[row, col] = 0.0
                continue
            p = 1.0
            for _ in range(e if e > 0 else -e):          # 10^|e|, exact for |e| <= 22
                p *= 10.0
            v = m * p if e >= 0 else m / p
            out[row, col] = -v if neg else v
        while i < n and _blank(c[i]):
            i += 1
        if i < n:
            if c[i] != 10:
                return -1                                # a fourth number, a colour, a comment
            i += 1
        row += 1
    return row if row == V else -1


if njit is not None:
    _blank = njit(cache=True, nogil=True, inline="always")(_blank)
    parse_vertex_lines = njit(cache=True, nogil=True)(parse_vertex_lines)
