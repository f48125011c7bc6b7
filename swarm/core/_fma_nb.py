"""A fused multiply-add for compiled kernels, and the 3 x 3 matrix-vector products that replace numba's BLAS
calls bit for bit.

Inside ``numba.njit`` code, ``A @ x`` on float64 arrays calls the BLAS's ``dgemv`` (through SciPy's
OpenBLAS) and allocates its result: for a 3 x 3 product the call, not the 15 flops, is what it costs. The
two functions below compute the same numbers in registers. OpenBLAS (0.3.30, its ``Haswell`` kernels, the
architecture this project's wheels select on an x86-64 with AVX2/FMA) computes a 3-row product in the
scalar tails of ``kernel/x86_64/dgemv_t_4.c`` / ``dgemv_n_4.c``: for ``A`` C-contiguous, ``A @ x`` is
``fma(a2, x2, fma(a0, x0, a1 x1))`` per row (the C compiler contracts ``a0 x0 + a1 x1 + a2 x2`` so), and
``A.T @ x`` is the plain ``(a0 x0 + a1 x1) + a2 x2`` per column (no contraction). Both equalities were checked
on 600 000 random rotations and vectors; the committed landing campaigns, which ran on the BLAS, reproduce
to the bit on them (tests/test_landing.py, tests/test_landing_moving.py).

:func:`fma` is LLVM's ``llvm.fma.f64``: ``a b + c`` rounded once (IEEE 754-2008 fusedMultiplyAdd).
"""

from __future__ import annotations

from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic


@intrinsic
def fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        fnty = ir.FunctionType(ir.DoubleType(), [ir.DoubleType()] * 3)
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.fma.f64")
        return builder.call(fn, args)

    return sig, codegen


@njit(cache=True)
def matvec3(a0, a1, a2, x0, x1, x2):
    """One row of ``A @ x`` for a C-contiguous 3 x 3 ``A`` (row ``(a0, a1, a2)``), as numba's ``dgemv``
    call computes it (module docstring)."""
    return fma(a2, x2, fma(a0, x0, a1 * x1))


@njit(cache=True)
def tmatvec3(a0, a1, a2, x0, x1, x2):
    """One entry of ``A.T @ x`` for a C-contiguous 3 x 3 ``A`` (column ``(a0, a1, a2)``), as numba's
    ``dgemv`` call computes it (module docstring)."""
    return a0 * x0 + a1 * x1 + a2 * x2
