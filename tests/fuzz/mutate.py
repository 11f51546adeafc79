"""A small seeded mutator for fuzzing the loaders (no dependencies beyond numpy).

:func:`mutate` applies one to three random edits to a file's bytes: byte flips,
insertions of random or interesting tokens, deletions, duplications, truncation,
and replacement of a number by an extreme value (huge integers, ``1e999``,
``2**31-1``, negative counts, NaN). Numbers are the interesting part of the
formats read here (counts, indices, list lengths), so half of the edits target them.
"""

from __future__ import annotations

import re

import numpy as np

__all__ = ["INTERESTING", "mutate"]

#: Replacement tokens that have broken loaders before (issue 24).
INTERESTING: tuple[bytes, ...] = (
    b"99999999999999999999", b"1e999", b"-1e999", b"nan", b"inf", b"-1", b"0", b"2147483647",
    b"4294967295", b"-2147483648", b"1000000000000", b"1e200", b"-0", b"1.5", b"a", b"", b"\x00",
    b"18446744073709551616", b"3", b"65535", b"255", b"1e-300",
)
_NUMBER = re.compile(rb"-?\d+(\.\d*)?(e-?\d+)?")


def _edit(data: bytes, rng: np.random.Generator) -> bytes:
    n = len(data)
    op = int(rng.integers(0, 10))
    if op <= 3:
        nums = list(_NUMBER.finditer(data))
        if nums:
            m = nums[int(rng.integers(0, len(nums)))]
            tok = INTERESTING[int(rng.integers(0, len(INTERESTING)))]
            return data[:m.start()] + tok + data[m.end():]
    if n == 0:
        return bytes(rng.integers(0, 256, int(rng.integers(1, 64)), dtype=np.uint8))
    i = int(rng.integers(0, n))
    if op == 4:  # flip bits of one byte
        return data[:i] + bytes([data[i] ^ int(rng.integers(1, 256))]) + data[i + 1:]
    if op == 5:  # insert random bytes
        junk = bytes(rng.integers(0, 256, int(rng.integers(1, 16)), dtype=np.uint8))
        return data[:i] + junk + data[i:]
    if op == 6:  # delete a range
        j = min(n, i + int(rng.integers(1, 64)))
        return data[:i] + data[j:]
    if op == 7:  # duplicate a range
        j = min(n, i + int(rng.integers(1, 64)))
        return data[:j] + data[i:j] + data[j:]
    if op == 8:  # truncate
        return data[:i]
    # insert an interesting token with spaces
    tok = INTERESTING[int(rng.integers(0, len(INTERESTING)))]
    return data[:i] + b" " + tok + b" " + data[i:]


def mutate(data: bytes, rng: np.random.Generator) -> bytes:
    """One mutated copy of ``data`` (1 to 3 edits; occasionally pure random bytes)."""
    if rng.random() < 0.02:
        return bytes(rng.integers(0, 256, int(rng.integers(1, 3000)), dtype=np.uint8))
    for _ in range(int(rng.integers(1, 4))):
        data = _edit(data, rng)
    return data
