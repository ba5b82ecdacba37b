"""native-rnnpb's C kernel (training, recognition, scoring): loading it, choosing the ISA.

ctypes only. The kernel itself is ``_native.c`` (an optional C extension
built at install); :mod:`iloci_native.rnnpb` calls it. Every instruction
set computes the same float32 arithmetic ("The float32 arithmetic" in
``_native.c``): forcing one with ``ILOCI_RNNPB_ISA`` changes the speed,
never a bit of the result.
"""

from __future__ import annotations

import ctypes
from functools import lru_cache
import os

from iloci.errors import IlociError

__all__ = ["ISAS", "ISA_ENV", "native_isas", "native_kernel_available", "kernel_info",
           "describe"]

#: Instruction sets of the native kernel, fastest first, by their names in
#: ``ILOCI_RNNPB_ISA`` and :func:`kernel_info`; values as in ``_native.c``.
ISAS = {"avx512": 3, "avx2": 2, "portable": 1}
#: Environment variable forcing the native kernel's instruction set (for
#: tests and benchmarks): ``avx512``, ``avx2``, ``portable``, or ``auto``
#: (unset: the fastest this CPU has).
ISA_ENV = "ILOCI_RNNPB_ISA"


#: Widest padded layer the native kernel trains (``WIDTH_MAX`` in ``_native.c``):
#: hidden and state units are padded to multiples of 16.
NATIVE_WIDTH_MAX = 256

#: What a non-zero return of ``iloci_rnnpb_train`` means.
NATIVE_CODES = {1: "out of memory", 2: "more than 256 hidden or state units",
                 3: "instruction set not supported here", 4: "malformed arguments"}


class TrainArgs(ctypes.Structure):
    """``iloci_rnnpb_train_args`` of ``_native.c``: the arguments of one training, by name."""

    _fields_ = [
        ("size", ctypes.c_int32), ("isa", ctypes.c_int32),
        ("epochs", ctypes.c_int32), ("T", ctypes.c_int32), ("R", ctypes.c_int32),
        ("D", ctypes.c_int32), ("C", ctypes.c_int32), ("H", ctypes.c_int32),
        ("P", ctypes.c_int32), ("warmup", ctypes.c_int32),
        ("alpha", ctypes.c_float), ("bound", ctypes.c_float),
        ("lr", ctypes.c_double), ("pb_lr", ctypes.c_double),
        ("decay", ctypes.c_double), ("clip", ctypes.c_double),
        ("X", ctypes.c_void_p), ("mw", ctypes.c_void_p),
        ("w_in", ctypes.c_void_p), ("b_hidden", ctypes.c_void_p),
        ("w_out", ctypes.c_void_p), ("b_out", ctypes.c_void_p), ("u", ctypes.c_void_p),
        ("loss_history", ctypes.c_void_p),
        ("loss", ctypes.c_float), ("epochs_run", ctypes.c_int32),
        ("isa_used", ctypes.c_int32),
    ]


class RecognizeArgs(ctypes.Structure):
    """``iloci_rnnpb_recognize_args`` of ``_native.c``: one recognition's arguments, by name."""

    _fields_ = [
        ("size", ctypes.c_int32), ("isa", ctypes.c_int32),
        ("steps", ctypes.c_int32), ("T", ctypes.c_int32), ("R", ctypes.c_int32),
        ("D", ctypes.c_int32), ("C", ctypes.c_int32), ("H", ctypes.c_int32),
        ("P", ctypes.c_int32), ("bound", ctypes.c_float),
        ("damping", ctypes.c_double), ("down", ctypes.c_double), ("up", ctypes.c_double),
        ("lam_min", ctypes.c_double), ("lam_max", ctypes.c_double),
        ("tiny", ctypes.c_double), ("u_max", ctypes.c_double),
        ("X", ctypes.c_void_p), ("sw", ctypes.c_void_p),
        ("w_in", ctypes.c_void_p), ("b_hidden", ctypes.c_void_p),
        ("w_out", ctypes.c_void_p), ("b_out", ctypes.c_void_p),
        ("u", ctypes.c_void_p), ("err", ctypes.c_void_p),
        ("isa_used", ctypes.c_int32),
    ]


@lru_cache(maxsize=1)
def native_lib() -> ctypes.CDLL | None:
    """The native kernel (``_native.c``), or None where it was not built."""
    try:
        from iloci_native import _native
    except ImportError:
        return None
    lib = ctypes.CDLL(_native.__file__)
    recognize_size = getattr(lib, "iloci_rnnpb_recognize_args_size", None)
    if (lib.iloci_rnnpb_train_args_size() != ctypes.sizeof(TrainArgs)
            or recognize_size is None or recognize_size() != ctypes.sizeof(RecognizeArgs)
            or not hasattr(lib, "iloci_rnnpb_errors")
            or not hasattr(lib, "iloci_rnnpb_generate64")):
        # a stale build of another layout: never pass it a struct it misreads
        return None
    lib.iloci_rnnpb_train.argtypes = [ctypes.POINTER(TrainArgs)]
    lib.iloci_rnnpb_train.restype = ctypes.c_int
    lib.iloci_rnnpb_recognize.argtypes = [ctypes.POINTER(RecognizeArgs)]
    lib.iloci_rnnpb_recognize.restype = ctypes.c_int
    lib.iloci_rnnpb_errors.argtypes = [ctypes.POINTER(RecognizeArgs)]
    lib.iloci_rnnpb_errors.restype = ctypes.c_int
    lib.iloci_rnnpb_isa_supported.argtypes = [ctypes.c_int]
    lib.iloci_rnnpb_generate64.argtypes = [ctypes.c_int32] * 6 + [ctypes.c_void_p] * 7
    lib.iloci_rnnpb_generate64.restype = ctypes.c_int
    return lib


def native_isas() -> tuple[str, ...]:
    """Instruction sets the native kernel can run here, fastest first (empty: not built)."""
    lib = native_lib()
    if lib is None:
        return ()
    return tuple(name for name, code in ISAS.items() if lib.iloci_rnnpb_isa_supported(code))


def native_kernel_available() -> bool:
    """Whether the native kernel was built (it then runs on every CPU, portable at worst)."""
    return native_lib() is not None


def requested_isa() -> str:
    """The instruction set ``ILOCI_RNNPB_ISA`` asks for, checked; ``"auto"`` when unset.

    Raises
    ------
    IlociError
        An unknown name, or one this CPU or build cannot run.
    """
    name = os.environ.get(ISA_ENV, "").strip().lower() or "auto"
    if name == "auto":
        return name
    if name not in ISAS:
        raise IlociError(f"{ISA_ENV}={name!r} is no instruction set of the native kernel; "
                         f"use one of auto, {', '.join(ISAS)}.")
    if name not in native_isas():
        have = ", ".join(native_isas()) or "none: the native kernel was not built"
        raise IlociError(f"{ISA_ENV}={name} asks for an instruction set this machine cannot "
                         f"run (available: {have}); unset it to use the fastest available.")
    return name


def kernel_info(kernel: str = "auto", dtype: str = "float32", fits: bool = True) -> str:
    """Which code a native-rnnpb model with these settings trains and recognizes with, in words.

    E.g. ``"native kernel (avx512)"``, ``"native kernel (portable; forced
    by ILOCI_RNNPB_ISA)"``, ``"numpy reference (float64: the native kernel
    is float32 only)"``. What ``iloci plugins`` prints and what a model
    says once when it is built on the numpy reference. ``fits``: whether
    the sizes fit the kernel (at most 256 hidden and state units).

    Raises
    ------
    IlociError
        ``ILOCI_RNNPB_ISA`` names an instruction set that cannot run here.
    """
    if dtype != "float32":
        return f"numpy reference ({dtype}: the native kernel is float32 only)"
    if not fits:
        return (f"numpy reference (more than {NATIVE_WIDTH_MAX} hidden or state units: "
                "beyond the native kernel)")
    if not native_kernel_available():
        return ("numpy reference (the native kernel was not built: reinstall iloci-native "
                "where a C compiler is available)")
    isa = requested_isa()
    if isa != "auto":
        return f"native kernel ({isa}; forced by {ISA_ENV})"
    return f"native kernel ({native_isas()[0]})"


def describe() -> str:
    """One line for ``iloci plugins``: what float32 training and recognition run on here."""
    try:
        return ("float32 training and recognition run the " + kernel_info()
                + "; the same bits on every instruction set")
    except IlociError as exc:
        return str(exc)
