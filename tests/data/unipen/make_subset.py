"""Make the small UNIPEN subsets under tests/data/unipen/ (run by hand).

    python tests/data/unipen/make_subset.py PATH/TO/train_r01_v07

``train_r01_v07``: three writers of ``aga`` (digits and letters).
``ibm/train_r01_v07``: the first ``IBM_SEGMENTS`` digit segments of three IBM
session files, two of one writer (``r01-04``, ``r02-04``) and one of another
(``r01-12``), and the ``ibm0.doc`` they include (its comments dropped).

Copies the category 1a (digits) and 1c (lower case) files of a few writers and
the files they include, keeping every .PEN_DOWN / .PEN_UP marker (so component
numbers stay those of the release) up to the last component a copied
.SEGMENT uses, and only the points of those components; of 1c only the
segments of LETTERS; header keywords are kept, comments dropped.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from iloci.data.unipen import _delineation

WRITERS = ["aga/amywldrp.dat", "aga/crlmtchl.dat", "aga/greghunt.dat"]
#: Letters kept from 1c (the tests use them as shapes never taught).
LETTERS = "acelos"
CATEGORIES = ["1a", "1c"]
OUT = Path(__file__).resolve().parent / "train_r01_v07"
IBM = ["ibm/ibm0/r0104.dat", "ibm/ibm0/r0204.dat", "ibm/ibm0/r0112.dat"]
IBM_SEGMENTS = 15
IBM_OUT = Path(__file__).resolve().parent / "ibm" / "train_r01_v07"


def main(src: str) -> None:
    subset(Path(src), WRITERS, CATEGORIES, OUT)
    subset(Path(src), IBM, ["1a"], IBM_OUT, segments=IBM_SEGMENTS)


def subset(root: Path, writers: list[str], categories: list[str], OUT: Path,
           segments: int | None = None) -> None:
    used: dict[str, set[int]] = {}
    for cat in categories:
        for w in writers:
            f = root / "data" / cat / w
            text = f.read_text(encoding="latin-1")
            incs = re.findall(r"^\.INCLUDE\s+(\S+)", text, re.M)
            if cat == "1c":
                text = "".join(line for line in text.splitlines(keepends=True)
                               if not line.startswith(".SEGMENT")
                               or re.search(f'"[{LETTERS}]"', line))
            if segments is not None:
                lines = text.splitlines(keepends=True)
                seg = [i for i, line in enumerate(lines) if line.startswith(".SEGMENT")]
                text = "".join(lines[:seg[segments]] if len(seg) > segments else lines)
            for doc in incs[:-1]:  # documentation files, included whole but for comments
                _copy_doc(root / "include" / doc, OUT / "include" / doc)
            segs = re.findall(r'^\.SEGMENT\s+\S+\s+(\S+)', text, re.M)
            (OUT / "data" / cat / w).parent.mkdir(parents=True, exist_ok=True)
            (OUT / "data" / cat / w).write_text(text, encoding="latin-1")
            comps = used.setdefault(incs[-1], set())
            for s in segs:
                comps.update(c for c, _, _ in _delineation(s, 10**9) or [])
    for inc, comps in used.items():
        lines, n, keep, comment = [], -1, False, False
        for line in (root / "include" / inc).read_text(encoding="latin-1").splitlines():
            if line.startswith(".PEN_DOWN") and n + 1 > max(comps):
                break
            if line.startswith("."):
                comment = line.startswith(".COMMENT")
                if line.startswith(".PEN_DOWN"):
                    n += 1
                    keep = n in comps
                elif line.startswith((".PEN_UP", ".DT")):
                    keep = False
                if not comment:
                    lines.append(line)
            elif keep and line.strip():
                lines.append(line)
            elif not comment and n < 0 and line.strip():
                lines.append(line)  # header values continued on the next lines
        out = OUT / "include" / inc
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text("\n".join(lines) + "\n", encoding="latin-1")


def _copy_doc(src: Path, out: Path) -> None:
    lines, comment = [], False
    for line in src.read_text(encoding="latin-1").splitlines():
        if line.startswith("."):
            comment = line.startswith(".COMMENT")
        if not comment:
            lines.append(line.rstrip())
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n", encoding="latin-1")


if __name__ == "__main__":
    main(sys.argv[1])
