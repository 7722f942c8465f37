"""Mutations of real files, seeded and repeatable: what truncated copies, flipped bits, other exporters'
quirks and hostile edits look like. Text mutations work on number tokens and lines; binary ones on bytes
and aligned 16/32-bit fields; JSON ones on parsed values."""
from __future__ import annotations

import json
import random
import re
import struct

EVIL_NUMBERS = ["nan", "NaN", "inf", "-inf", "1e308", "-1e308", "1e400", "1e40", "-1", "0", "-0",
                "99999999999999999999", "9223372036854775808", "-2147483649", "", "abc", "0x10", "1e-320"]
_NUMBER = re.compile(rb"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")


def truncate(data: bytes, rng: random.Random) -> bytes:
    return data[: rng.randrange(0, max(1, len(data)))]


def flip_bytes(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        if b:
            b[rng.randrange(len(b))] = rng.randrange(256)
    return bytes(b)


def zero_range(data: bytes, rng: random.Random) -> bytes:
    if not data:
        return data
    i = rng.randrange(len(data))
    n = rng.randint(1, 512)
    return data[:i] + bytes(min(n, len(data) - i)) + data[i + n:]


def extreme_field(data: bytes, rng: random.Random) -> bytes:
    """An aligned int16/int32/float32 field set to an extreme: counts, offsets, scales and rates in binary
    headers live in such fields."""
    if len(data) < 8:
        return data
    b = bytearray(data)
    size = rng.choice([2, 4])
    i = rng.randrange(0, (len(b) - size) // size) * size
    if rng.random() < 0.3:
        i = rng.randrange(0, min(len(b) - size, 1024) // size) * size   # headers are at the start
    if size == 2:
        v = struct.pack("<h", rng.choice([0, -1, 32767, -32768, 1, 255]))
    else:
        v = rng.choice([struct.pack("<i", x) for x in (0, -1, 2**31 - 1, -2**31, 10**9)]
                       + [struct.pack("<f", x) for x in (float("nan"), float("inf"), -float("inf"), 1e38, 0.0)])
    b[i:i + size] = v
    return bytes(b)


def evil_number(data: bytes, rng: random.Random) -> bytes:
    hits = list(_NUMBER.finditer(data[:2_000_000]))
    if not hits:
        return flip_bytes(data, rng)
    out = data
    for m in sorted(rng.sample(hits, min(len(hits), rng.randint(1, 3))), key=lambda m: -m.start()):
        out = out[: m.start()] + rng.choice(EVIL_NUMBERS).encode() + out[m.end():]
    return out


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)


def delete_line(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if lines:
        del lines[rng.randrange(len(lines))]
    return b"".join(lines)


def duplicate_line(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if lines:
        i = rng.randrange(len(lines))
        lines.insert(i, lines[i])
    return b"".join(lines)


def swap_lines(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if len(lines) > 1:
        i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
        lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines)


def long_cell(data: bytes, rng: random.Random) -> bytes:
    i = rng.randrange(len(data) + 1)
    return data[:i] + b"9" * rng.choice([1000, 140_000]) + data[i:]


def separators(data: bytes, rng: random.Random) -> bytes:
    a, b = rng.choice([(b"\t", b"\t\t"), (b",", b";"), (b"\n", b"\r\n"), (b" ", b"\t"), (b"\t", b" ")])
    return data.replace(a, b)


BINARY = [truncate, flip_bytes, zero_range, extreme_field, extreme_field]
TEXT = [truncate, flip_bytes, evil_number, evil_number, evil_number, delete_line, duplicate_line, swap_lines,
        long_cell, separators]


def mutate_json_value(doc, rng: random.Random):
    """Replace one value somewhere in a parsed JSON document by a value of another type or an extreme."""
    choices = [None, "x", [], {}, -1, 0, 2**63, 1e308, -1e308, [1, 2, 3], "nan", True, [[0]], 0.5]
    nodes = []

    def walk(node, parent, key):
        nodes.append((parent, key))
        if isinstance(node, dict):
            for k, v in list(node.items()):
                walk(v, node, k)
        elif isinstance(node, list):
            for i, v in enumerate(node[:50]):
                walk(v, node, i)
    walk(doc, None, None)
    parent, key = rng.choice(nodes[1:] or nodes)
    if parent is None:
        return rng.choice(choices)
    parent[key] = rng.choice(choices)
    return doc


def mutate_json(data: bytes, rng: random.Random) -> bytes:
    try:
        doc = json.loads(data)
    except ValueError:
        return rng.choice(TEXT)(data, rng)
    roll = rng.random()
    if roll < 0.1:
        return b"[" * 100_000 + b"]" * 100_000   # nesting deeper than any parser's recursion
    if roll < 0.25:
        return evil_number(data, rng)
    for _ in range(rng.randint(1, 3)):
        doc = mutate_json_value(doc, rng)
    text = json.dumps(doc)
    if rng.random() < 0.2:   # values json.dumps cannot write
        text = text.replace("1e+308", rng.choice(["1e400", "NaN", "Infinity", "-1e999"]), 1)
    return text.encode()
