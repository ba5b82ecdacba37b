"""Golden outputs: what a refactoring must not move, recorded and compared bit for bit.

Issue 28's guard. A golden record is plain JSON: numbers are kept as
Python writes them (``repr``, which round-trips every float64 exactly), so
two records are equal only when every value is the same bit for bit. Large
parts (a fold's per-demonstration lists, a memory file's arrays) are kept
as SHA-256 digests of their canonical JSON or bytes, so a mismatch still
says *which* part moved.

Used by ``tests/test_golden.py`` (a scripted step-wise session and the
memory file it saves: cheap, every test run) and ``benchmarks/golden.py``
(the main job's ``metrics.json`` on seeds 0 and 1, ``quality.json``'s
``best`` and ``noisy-0.1`` rows on seed 0: minutes). Regenerating them is
documented in docs/development.md, "Golden outputs".
"""

from __future__ import annotations

from collections.abc import Mapping
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["canonical", "digest", "differences", "memory_record", "read_golden",
           "write_golden"]


def canonical(value: Any) -> Any:
    """``value`` as plain JSON types: arrays to nested lists, tuples to lists, keys to str."""
    if isinstance(value, np.ndarray):
        return canonical(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): canonical(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [canonical(v) for v in value]
    return value


def digest(value: Any) -> str:
    """SHA-256 (hex, first 16 bytes) of ``value``'s canonical, key-sorted JSON.

    Floats are written with ``repr``, so the digest changes when any bit of
    any number does.
    """
    text = json.dumps(canonical(value), sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode()).hexdigest()[:32]


def memory_record(path: str | os.PathLike[str]) -> dict[str, Any]:
    """What a saved memory file holds, bit for bit, without its zip container.

    The ``.npz`` container records file times, so the file's own bytes
    differ between two identical saves; this compares what is in it: the
    JSON header (less the iloci version and the checkout's directory in the
    robot's URDF path) and a digest of each array's dtype,
    shape and bytes.

    Returns
    -------
    dict
        ``{"header": {...}, "arrays": {name: digest}}``.
    """
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}
    header = json.loads(arrays.pop("__header__").tobytes().decode("utf-8"))
    header.pop("iloci", None)
    header.pop("checksum", None)   # a digest of the arrays, compared one by one below
    robot = header.get("robot")
    if isinstance(robot, dict) and isinstance(robot.get("urdf"), str):
        robot["urdf"] = Path(robot["urdf"]).name   # where the checkout is: not a result
    return {"header": canonical(header),
            "arrays": {name: hashlib.sha256(
                f"{a.dtype.str}{a.shape}".encode() + np.ascontiguousarray(a).tobytes()
            ).hexdigest()[:32] for name, a in sorted(arrays.items())}}


def differences(expected: Any, got: Any, where: str = "") -> list[str]:
    """Every place where two golden records differ, as ``"path: expected != got"`` lines.

    Floats compare bit for bit (NaN equals NaN).
    """
    if isinstance(expected, dict) and isinstance(got, dict):
        out = []
        for k in sorted(set(expected) | set(got)):
            p = f"{where}.{k}" if where else str(k)
            if k not in got:
                out.append(f"{p}: missing now")
            elif k not in expected:
                out.append(f"{p}: new (not in the golden record)")
            else:
                out.extend(differences(expected[k], got[k], p))
        return out
    if isinstance(expected, list) and isinstance(got, list):
        if len(expected) != len(got):
            return [f"{where}: {len(expected)} items != {len(got)} items"]
        return [d for i, (a, b) in enumerate(zip(expected, got))
                for d in differences(a, b, f"{where}[{i}]")]
    if isinstance(expected, float) and isinstance(got, float) \
            and np.isnan(expected) and np.isnan(got):
        return []
    if type(expected) is not type(got) or expected != got:
        return [f"{where}: {expected!r} != {got!r}"]
    return []


def read_golden(path: str | os.PathLike[str]) -> Any:
    """A golden record written by :func:`write_golden`."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_golden(path: str | os.PathLike[str], record: Any) -> None:
    """Write a golden record (indented, key-sorted JSON)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(canonical(record), indent=1, sort_keys=True, allow_nan=True)
                 + "\n", encoding="utf-8")
