"""Fuzzing past the bytes (issue 42): structure-aware BVH and AMC, zip-member bombs and output
targets, for :mod:`imuloco.lab.fuzz`.

- ``bvh-structure``: a valid BVH rebuilt with its structure changed: huge lines of tokens
  (header, joint name, MOTION row), blank and odd line breaks, joints swapped, names repeated,
  braces unbalanced, rows too wide, frame counts near the frames x joints limit.
- ``amc-structure``: an AMC with bones missing or repeated in a frame, frame numbers skipped,
  huge lines, many short frames, radians, unknown bones.
- ``zip-members``: an app export zip whose members are bombs (bzip2 or deflate line breaks,
  stored line breaks after a header), preambles of blank lines, sizes the directory misstates.
- ``outputs``: writing an output (``check_outputs`` then an :class:`~imuloco.io.atomic.OutputSet`,
  as the commands do) over a FIFO, a link to ``/proc/self/fd/1``, a device node, a folder, a
  link to a file, or two outputs at one path (through ``..`` or a linked folder). Garbage
  accepted here is a special file replaced, or two outputs written to one path.

Sizes stay within what a reader gets through in the fuzzer's 5 s on a loaded machine (the AMC
reader takes 4.2 s for 50,000 frames, 2.5 MB: throughput, not a hang); the memory of larger
inputs is bounded by the tests (tests/test_bvh.py, tests/test_asf_amc.py).
"""

from __future__ import annotations

import json
import os
import random
import stat
import zipfile
from pathlib import Path

from imuloco.io.atomic import OutputSet, check_outputs
from imuloco.lab.mutations import Files, unzip, zip_files


# ---- BVH and AMC ----------------------------------------------------------------------------
def bvh_structure_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    name, data = next(iter(files.items()))
    text = data.decode()
    head, motion = text.split("MOTION", 1)
    kind = rng.choice(("header-line", "name-words", "motion-line", "blank-lines", "odd-breaks",
                       "swap-joints", "repeat-name", "unbalanced", "wide-rows", "many-frames",
                       "no-end-site", "cr-only"))
    zeros = "0 " * rng.choice((1_000, 100_000, 1_000_000))
    if kind == "header-line":
        text = text.replace("OFFSET", "OFFSET " + zeros, 1)
    elif kind == "name-words":
        text = text.replace("JOINT ", "JOINT " + "w " * rng.choice((65, 10_000)), 1)
    elif kind == "motion-line":
        lines = text.splitlines()
        k = rng.randrange(len(lines) - 5, len(lines))
        lines[k] = zeros
        text = "\n".join(lines)
    elif kind == "blank-lines":
        at = rng.choice((len(head), len(text) - len(motion) // 2))
        text = text[:at] + "\n" * rng.choice((100, 10_000, 100_000)) + text[at:]
    elif kind == "odd-breaks":
        text = text.replace("\n", rng.choice(("\r", "\x0b", "\u2028", "\x85")))
    elif kind == "swap-joints":
        blocks = head.split("JOINT ")
        if len(blocks) > 3:
            i, j = rng.sample(range(1, len(blocks)), 2)
            blocks[i], blocks[j] = blocks[j], blocks[i]
        text = "JOINT ".join(blocks) + "MOTION" + motion
    elif kind == "repeat-name":
        names = [ln.split()[1] for ln in head.splitlines() if ln.strip().startswith("JOINT")]
        text = text.replace(f"JOINT {names[-1]}", f"JOINT {rng.choice(names[:-1])}", 1)
    elif kind == "unbalanced":
        lines = text.splitlines()
        braces = [i for i, ln in enumerate(lines) if ln.strip() in ("{", "}")]
        k = rng.choice(braces)
        lines[k] = rng.choice(("", "{ {", "} }", "}"))
        text = "\n".join(lines)
    elif kind == "wide-rows":
        text = "\n".join(ln + " 0" if ln[:1].isdigit() or ln[:1] == "-" else ln
                         for ln in text.splitlines())
    elif kind == "many-frames":
        lines = motion.strip().splitlines()
        rows = [ln for ln in lines[2:] if ln.strip()]
        rows = rows * rng.choice((10, 100))
        text = f"{head}MOTION\nFrames: {len(rows) + rng.choice((0, 0, 1, -1))}\n{lines[1]}\n" \
               + "\n".join(rows) + "\n"
    elif kind == "no-end-site":
        text = text.replace("End Site", "", 1)
    else:
        text = text.replace("\r\n", "\n").replace("\n", "\r\n")
        text = text[: len(text) // 2] + "\r" + text[len(text) // 2:]
    return f"structure:{kind}", {name: text.encode()}


def amc_structure_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    names = list(files)
    asf, amc = files[names[0]], files[names[1]].decode()
    lines = amc.splitlines()
    frames = [i for i, ln in enumerate(lines) if ln.strip().isdigit()]
    kind = rng.choice(("missing-bone", "bone-twice", "frame-gap", "long-line", "many-frames",
                       "radians", "unknown-bone", "frame-number", "no-frames", "blank-lines"))
    if kind == "missing-bone":
        k = rng.choice([i for i in range(len(lines)) if i not in frames and i > 1])
        del lines[k]
    elif kind == "bone-twice":
        k = rng.choice([i for i in range(len(lines)) if i not in frames and i > 1])
        lines.insert(k, lines[k])
    elif kind == "frame-gap":
        k = rng.choice(frames[1:])
        lines[k] = str(int(lines[k]) + rng.choice((1, 1000)))
    elif kind == "long-line":
        k = rng.randrange(2, len(lines))
        lines[k] = lines[k] + " 0" * rng.choice((10, 100_000))
    elif kind == "many-frames":
        body = lines[frames[0]:frames[1]]
        start = len(frames)
        for f in range(rng.choice((1_000, 10_000))):
            lines += [str(start + 1 + f), *body[1:]]
    elif kind == "radians":
        lines = [":RADIANS" if ln == ":DEGREES" else ln for ln in lines]
    elif kind == "unknown-bone":
        lines.insert(frames[0] + 1, "nobody 0 0 0")
    elif kind == "frame-number":
        lines[frames[0]] = rng.choice(("0", "999999999", "1" * 40))
    elif kind == "no-frames":
        lines = lines[:2]
    else:
        lines.insert(rng.randrange(len(lines)), "\n" * rng.choice((1_000, 100_000)))
    return f"structure:{kind}", {names[0]: asf, names[1]: ("\n".join(lines) + "\n").encode()}


# ---- zip members ----------------------------------------------------------------------------
def zip_member_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    name, data = next(iter(files.items()))
    members = unzip(data)
    target = rng.choice(sorted(m for m in members if m != "Metadata.csv"))
    kind = rng.choice(("bzip2-newlines", "deflate-newlines", "stored-blank-body", "preamble",
                       "lzma-zeros", "header-only", "sub-folder", "empty"))
    method = zipfile.ZIP_DEFLATED
    size = rng.choice((1 << 20, 16 << 20, 64 << 20))
    if kind == "bzip2-newlines":
        members[target], method = b"\n" * size, zipfile.ZIP_BZIP2
    elif kind == "deflate-newlines":
        members[target] = b"\n" * size
    elif kind == "stored-blank-body":
        head, _, rest = members[target].partition(b"\n")
        members[target] = head + b"\n" + b"\n" * rng.choice((100_000, 4 << 20)) + rest
        method = zipfile.ZIP_STORED
    elif kind == "preamble":
        members[target] = b"\n" * rng.choice((999, 1_001, 100_000)) + members[target]
    elif kind == "lzma-zeros":
        members[target], method = b"0" * size, zipfile.ZIP_LZMA
    elif kind == "header-only":
        members[target] = members[target].split(b"\n", 1)[0] + b"\n"
    elif kind == "sub-folder":
        members = {f"{'deep/' * rng.choice((1, 50))}{k}": v for k, v in members.items()}
    else:
        members[target] = b""
    return f"zip:{kind}", {name: zip_files(members, method)}


# ---- output targets -------------------------------------------------------------------------
TARGETS = ("new", "regular", "fifo", "link-stdout", "link-file", "dangling-link", "device",
           "folder", "same-path", "same-via-link", "input")


def output_seeds() -> list[Files]:
    return [{"spec.json": json.dumps({"kind": "new"}).encode()}]


def output_attack(files: Files, rng: random.Random) -> tuple[str, Files]:
    kind = rng.choice(TARGETS)
    return f"target:{kind}", {"spec.json": json.dumps({"kind": kind}).encode()}


def write_outputs(spec_path: Path) -> dict:
    """Make the target a spec file asks for beside it, write over it as the commands do
    (``check_outputs`` with ``--force``, then an ``OutputSet``), and say what became of it."""
    folder = spec_path.parent
    kind = json.loads(spec_path.read_text()).get("kind", "new")
    a = folder / "a.bvh"
    targets, inputs = [a], [spec_path]
    if kind == "regular":
        a.write_text("old")
    elif kind == "fifo":
        os.mkfifo(a)
    elif kind == "link-stdout":
        a.symlink_to("/proc/self/fd/1")
    elif kind == "link-file":
        (folder / "kept.txt").write_text("kept")
        a.symlink_to(folder / "kept.txt")
    elif kind == "dangling-link":
        a.symlink_to(folder / "nowhere.txt")
    elif kind == "device":
        try:  # a node like /dev/null, in the fuzzer's own folder: replacing it harms nothing
            os.mknod(a, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        except (PermissionError, OSError):
            a.symlink_to("/dev/null")
    elif kind == "folder":
        a.mkdir()
    elif kind == "same-path":
        (folder / "sub").mkdir()
        targets = [a, folder / "sub" / ".." / "a.bvh"]
    elif kind == "same-via-link":
        (folder / "real").mkdir()
        (folder / "alias").symlink_to(folder / "real")
        targets = [folder / "real" / "a.bvh", folder / "alias" / "a.bvh"]
    elif kind == "input":
        targets = [spec_path]
    before = os.lstat(targets[0]).st_mode if os.path.lexists(targets[0]) else None
    check_outputs(targets, force=True, inputs=inputs)
    with OutputSet() as outs:
        for k, t in enumerate(targets):
            outs.path(t).write_text(f"output {k}")
    return {"kind": kind, "before": before,
            "after": [os.lstat(t).st_mode if os.path.lexists(t) else None for t in targets],
            "texts": [Path(t).read_text() if os.path.isfile(t) else None for t in targets]}


def output_garbage(result: dict) -> str | None:
    """Why a write that went through is wrong: a special file replaced, two outputs at one
    path, or an output that is not what was written."""
    before, after = result["before"], result["after"]
    if before is not None and not stat.S_ISREG(before):
        return f"{result['kind']}: a {stat.filemode(before)} target was replaced"
    if len(after) > 1 and len(set(result["texts"])) < len(after):
        return f"{result['kind']}: two outputs written to one path"
    if any(m is None or not stat.S_ISREG(m) for m in after):
        return f"{result['kind']}: an output is not a regular file"
    return None
