"""Make the small UNIPEN subset under tests/data/unipen/train_r01_v07 (run by hand).

    python tests/data/unipen/make_subset.py PATH/TO/train_r01_v07

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


def main(src: str) -> None:
    root = Path(src)
    used: dict[str, set[int]] = {}
    for cat in CATEGORIES:
        for w in WRITERS:
            f = root / "data" / cat / w
            text = f.read_text(encoding="latin-1")
            incs = re.findall(r"^\.INCLUDE\s+(\S+)", text, re.M)
            if cat == "1c":
                text = "".join(line for line in text.splitlines(keepends=True)
                               if not line.startswith(".SEGMENT")
                               or re.search(f'"[{LETTERS}]"', line))
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


if __name__ == "__main__":
    main(sys.argv[1])
