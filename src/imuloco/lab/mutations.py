"""The input-mutation engine: random edits of a file's bytes and lines, and the container
forgeries (zip members, claimed sizes, ``.npy`` arrays) the fuzzer's attacks are built from.

One engine for both users: ``imuloco bench --fuzz`` (:mod:`imuloco.lab.fuzz`, seeded by a
:class:`random.Random`) and the readers' property tests, through the hypothesis strategy
:func:`mutations`. Every function takes the random source it draws from and draws in a fixed
order: a seed gives the same inputs on every run.
"""

from __future__ import annotations

import io
import random
import zipfile
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from hypothesis.strategies import SearchStrategy

Files = dict[str, bytes]  # file name -> content; the first file is the one read

# cells an edit writes into a table or a header: extreme, non-finite, malformed numbers
ATTACK_NUMBERS = ("1e308", "-1e308", "1e309", "nan", "inf", "-inf", "0", "-0", "1e-9", "1e-300",
                  "5e-324", "1e6", "1e7", "-1", "99999999999999999999999", "", "x", "0x10",
                  "1_000", "１２", "\x00", '"', "1,5", "1e", "--1", " ", "\t")


def mutate_bytes(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """One byte edit (flip, insert, delete, duplicate, truncate, zero) of 1 to 512 bytes at a
    random place; returns its label (``bytes:OP``) and the edited bytes."""
    b = bytearray(data)
    op = rng.choice(("flip", "insert", "delete", "duplicate", "truncate", "zero"))
    if not b:  # truncated to nothing by an earlier step: only inserting changes it
        op = "insert"
    i = rng.randrange(len(b)) if b else 0
    n = rng.choice((1, 1, 2, 8, 64, 512))
    if op == "flip":
        for _ in range(n):
            b[rng.randrange(len(b))] = rng.randrange(256)
    elif op == "insert":
        b[i:i] = bytes(rng.randrange(256) for _ in range(n))
    elif op == "delete":
        del b[i:i + n]
    elif op == "duplicate":
        b[i:i] = b[i:i + n * 8]
    elif op == "truncate":
        del b[i:]
    else:
        b[i:i + n] = bytes(min(n, len(b) - i))
    return f"bytes:{op}", bytes(b)


def mutate_lines(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """One line edit (delete, duplicate, swap, repeat up to 5,000 times, or cells replaced by
    :data:`ATTACK_NUMBERS`); returns its label (``lines:OP``) and the edited bytes."""
    lines = data.split(b"\n")
    op = rng.choice(("delete", "duplicate", "swap", "repeat", "cell"))
    i, j = rng.randrange(len(lines)), rng.randrange(len(lines))
    if op == "delete":
        del lines[i]
    elif op == "duplicate":
        lines.insert(i, lines[j])
    elif op == "swap":
        lines[i], lines[j] = lines[j], lines[i]
    elif op == "repeat":
        lines[i:i] = [lines[i]] * rng.choice((2, 100, 5000))
    else:
        for _ in range(rng.choice((1, 1, 3, 20))):
            k = rng.randrange(len(lines))
            cells = lines[k].replace(b"\t", b" ").replace(b",", b" ").split(b" ")
            c = rng.randrange(len(cells))
            cells[c] = rng.choice(ATTACK_NUMBERS).encode()
            sep = b"," if b"," in lines[k] else b" "
            lines[k] = sep.join(cells)
    return f"lines:{op}", b"\n".join(lines)


EDITS = {"bytes": mutate_bytes, "lines": mutate_lines}


def mutate(data: bytes, rng: random.Random, steps: int = 1,
           kinds: tuple[str, ...] = ("bytes", "lines")) -> tuple[str, bytes]:
    """``steps`` edits of ``data``, each of :data:`EDITS`' first or last of ``kinds`` (even
    odds); returns the edits' labels joined by ``+`` and the edited bytes."""
    labels = []
    for _ in range(steps):
        edit = EDITS[kinds[0] if rng.random() < 0.5 else kinds[-1]]
        label, data = edit(data, rng)
        labels.append(label)
    return "+".join(labels), data


def mutations(data: str | bytes, max_steps: int = 6,
              kinds: tuple[str, ...] = ("bytes",)) -> SearchStrategy[bytes]:
    """A hypothesis strategy of ``data`` after 1 to ``max_steps`` edits of :func:`mutate`
    (the tests' form of the engine; hypothesis draws the seed of the edits' random source)."""
    from hypothesis import strategies as st  # the [dev] extra's: only tests draw strategies

    raw = data.encode() if isinstance(data, str) else data
    return st.tuples(st.integers(1, max_steps), st.integers(0, 2**32 - 1)).map(
        lambda a: mutate(raw, random.Random(a[1]), a[0], kinds)[1])


# ---------------------------------------------------------------------------------------------
# containers: zip archives and .npy arrays

def zip_files(files: Files, method: int = zipfile.ZIP_DEFLATED) -> bytes:
    """A zip archive of ``files`` (member name -> content), compressed by ``method``."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", method) as z:
        for name, data in files.items():
            z.writestr(name, data)
    return buf.getvalue()


def unzip(data: bytes) -> Files:
    """The members of a zip archive, by name."""
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return {i.filename: z.read(i) for i in z.infolist()}


def claim_size(data: bytes, member: str, size: int) -> bytes:
    """A zip whose central directory claims ``size`` uncompressed bytes for ``member``."""
    b = bytearray(data)
    sig, name = b"PK\x01\x02", member.encode()
    at = b.find(sig)
    while at >= 0:
        n = int.from_bytes(b[at + 28:at + 30], "little")
        if bytes(b[at + 46:at + 46 + n]) == name:
            b[at + 24:at + 28] = min(size, 0xFFFFFFFE).to_bytes(4, "little")
        at = b.find(sig, at + 46)
    return bytes(b)


def npy(arr: np.ndarray) -> bytes:
    """``arr`` as the bytes of a ``.npy`` file (no pickles)."""
    buf = io.BytesIO()
    np.lib.format.write_array(buf, arr, allow_pickle=False)
    return buf.getvalue()
