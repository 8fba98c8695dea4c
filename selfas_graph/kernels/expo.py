"""An exponential that vectorises: ``exp(x)`` for ``x <= 0`` to within 2 ulp of ``math.exp``.

numba lowers ``math.exp`` to a call into libm, and LLVM cannot vectorise a loop that
calls it without Intel's SVML (absent on the 2-core machine, and not something to
depend on). Written out in arithmetic, the exponential vectorises with the loop around
it. Derivation (Cody and Waite's range reduction):

``exp(x) = 2^n exp(r)``, ``n = round(x / ln 2)``, ``r = x - n ln 2`` with ``|r| <= ln 2 / 2``,
where ``n ln 2`` is subtracted in two parts (``LN2_HI`` has its low 11 bits zero, so
``n LN2_HI`` is exact for ``|n| < 2^11``). ``exp(r)`` is its Taylor series to degree
13, whose remainder ``|r|^14 / 14! < 5e-18`` is below half an ulp. The polynomial is
evaluated by Estrin's scheme (pairs of terms, then pairs of pairs with ``r^2``, ``r^4``,
``r^8``): a tree four multiply-adds deep instead of Horner's chain of 13, so that the
vectorised pair loop around it is not held up waiting on one long chain per pair
(measured on one core of the AVX2 Zen 3: the Yukawa sum over a 1200-rod list 2.8 -> 2.4 ms,
over all pairs 10.6 -> 8.0 ms; docs/performance.md). Its rounding adds at most about 1 ulp,
like Horner's; the two differ in the last bit for some x. ``2^n`` is made from the bits of a double; for results
below the smallest normal double it is applied as two factors so that each stays
normal (the product then rounds once, into the subnormals, like libm).

Special values: ``exp(0) = 1``; ``x < -745.2`` gives 0 (the true value is below half
the smallest subnormal); NaN gives NaN. Meant for ``x <= 0``: positive ``x`` is
computed the same way but only up to ``x < 709`` (no overflow handling).

:func:`exp_nonpositive_f32` is the same construction in float32, for the mixed-precision Yukawa
sum (8 lanes a vector with AVX2): ``n LN2_HI_F32`` is exact (``LN2_HI_F32`` has 16 significant
bits, ``|n| <= 126``), the polynomial is the Taylor series to degree 7 (remainder
``|r|^8 / 8! < 5.2e-9``, below a tenth of a float32 ulp of ``exp(r) >= 0.7``) and ``2^-n`` is made
from the bits of a float32. Its results are normal or 0: below ``EXP_F32_MIN`` (the float32 just
above ``ln`` of the smallest normal float32, about -87.3365) it returns 0, where the true value
is below the smallest normal ``1.2e-38`` (no subnormal results; -inf gives 0 too). NaN gives NaN.
"""

import struct

import numba
import numpy as np
from numba.core import types
from numba.extending import intrinsic

from ._jit import inline

LOG2E = 1.4426950408889634
LN2_HI = 6.93147180369123816490e-01  # ln 2 rounded to 32 significant bits
LN2_LO = 1.90821492927058770002e-10  # ln 2 - LN2_HI

#: float32 constants of :func:`exp_nonpositive_f32`: a float64 literal would promote the loop around it to float64
LOG2E_F32 = np.float32(1.4426950408889634)
LN2_HI_F32 = np.float32(0.693145751953125)  # ln 2 truncated to 16 significant bits: n LN2_HI_F32 is exact
LN2_LO_F32 = np.float32(1.4286068202862268e-06)  # ln 2 - LN2_HI_F32, rounded to float32
#: below this exp_nonpositive_f32 returns 0: the float32 just above ln(1.1754944e-38), the smallest normal
EXP_F32_MIN = np.float32(-87.33654022216797)
_F32_HALF = np.float32(0.5)
_F32_ZERO = np.float32(0.0)
_F32_N_MAX = np.float32(126.5)  # t = -x log2(e) + 1/2 at EXP_F32_MIN: floor(t) = n <= 126, 2^-n normal
_F32_N_MIN = np.float32(-126.0)
#: Taylor coefficients 1/k!, k = 0 .. 7, rounded to float32
_F32_C = tuple(np.float32(1.0 / f) for f in (1, 1, 2, 6, 24, 120, 720, 5040))


if numba.config.DISABLE_JIT:
    # NUMBA_DISABLE_JIT=1 runs every kernel as Python (to step through it in a debugger); an
    # intrinsic has no Python body, so each gets one here, with the same result bit for bit.

    def _double_from_bits(bits):
        """The double whose IEEE bits are the int64 ``bits``."""
        return struct.unpack("<d", struct.pack("<q", int(bits)))[0]

    def _pow2_f32(m):
        """``2^m`` as a float32, for an integral float32 ``-126 <= m <= 127``, from its bits."""
        return np.frombuffer(struct.pack("<i", (int(m) + 127) << 23), dtype=np.float32)[0]

    def _trunc_int32(value):
        """``int(value)`` (truncation towards zero) for a double well inside the int32 range, as an int."""
        return int(value)

else:

    @intrinsic
    def _double_from_bits(typingctx, bits):
        """The double whose IEEE bits are the int64 ``bits`` (a register move, vectorisable)."""
        sig = types.float64(types.int64)

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(types.float64))

        return sig, codegen

    @intrinsic
    def _trunc_int32(typingctx, value):
        """``int(value)`` for a double known to lie well inside the int32 range, as an int64.

        The conversion goes through int32 (``fptosi`` to i32, then sign extension) because
        AVX2 converts four doubles to int32 in one instruction (``vcvttpd2dq``) but has no
        packed double-to-int64 conversion (that is AVX-512DQ's ``vcvttpd2qq``): ``int(t)``
        in int64 made LLVM convert the lanes one at a time (``vcvttsd2si``) inside the
        vectorised Yukawa pair loop. The value is the same.
        """
        sig = types.int64(types.float64)

        def codegen(context, builder, signature, args):
            from llvmlite import ir

            return builder.sext(builder.fptosi(args[0], ir.IntType(32)), ir.IntType(64))

        return sig, codegen

    @intrinsic
    def _pow2_f32(typingctx, m):
        """``2^m`` as a float32, for an integral float32 ``-126 <= m <= 127``: the int32
        ``(m + 127) << 23`` as the bits of a float32.

        All in 32-bit lanes (``fptosi`` to i32, an add, a shift, ``bitcast``), so that AVX2 does 8
        at a time (``vcvttps2dq``, ``vpaddd``, ``vpslld``); numba's own integers are int64.
        """
        sig = types.float32(types.float32)

        def codegen(context, builder, signature, args):
            from llvmlite import ir

            i32 = ir.IntType(32)
            bits = builder.shl(builder.add(builder.fptosi(args[0], i32), ir.Constant(i32, 127)), ir.Constant(i32, 23))
            return builder.bitcast(bits, context.get_value_type(types.float32))

        return sig, codegen


@inline
def _pow2(m):
    """``2^m`` for an integer ``-1022 <= m <= 1023``, from its bits."""
    return _double_from_bits((m + 1023) << 52)


@inline
def exp_nonpositive(x):
    """``exp(x)`` for ``x <= 0``, within 2 ulp of ``math.exp`` (module docstring)."""
    # NaN fails every comparison: it keeps its value here and is clamped below only in t
    x = -745.2 if x < -745.2 else x
    t = -x * LOG2E + 0.5
    t = t if t < 1076.0 else 1076.0  # also catches NaN, so that n is a defined integer
    t = t if t > -1023.0 else -1023.0
    i = _trunc_int32(t)  # |t| <= 1076: int32 holds it, and AVX2 converts to int32 four at a time
    n = i if t >= 0.0 else i - 1  # floor(t) = round(-x / ln 2)
    r = (x + n * LN2_HI) + n * LN2_LO  # x - (-n) ln 2
    # Estrin's scheme for sum_k r^k / k!, k = 0 .. 13 (module docstring)
    r2 = r * r
    r4 = r2 * r2
    r8 = r4 * r4
    a01 = 1.0 + r
    a23 = 0.5 + r * (1.0 / 6.0)
    a45 = 1.0 / 24.0 + r * (1.0 / 120.0)
    a67 = 1.0 / 720.0 + r * (1.0 / 5040.0)
    a89 = 1.0 / 40320.0 + r * (1.0 / 362880.0)
    a1011 = 1.0 / 3628800.0 + r * (1.0 / 39916800.0)
    a1213 = 1.0 / 479001600.0 + r * (1.0 / 6227020800.0)
    b03 = a01 + r2 * a23
    b47 = a45 + r2 * a67
    b811 = a89 + r2 * a1011
    c07 = b03 + r4 * b47
    c813 = b811 + r4 * a1213
    p = c07 + r8 * c813
    # exp(x) = p 2^(-n), as two normal factors 2^(-h) 2^(-(n - h)) with h = n // 2
    h = n >> 1
    return p * _pow2(-h) * _pow2(h - n)


@inline
def exp_nonpositive_f32(x):
    """``exp(x)`` for a float32 ``x <= 0``, as a float32, within 2 float32 ulp of ``math.exp``.

    0 for ``x < EXP_F32_MIN`` (about -87.3365, where the true value is below the smallest normal
    float32; no subnormal results), NaN for NaN (module docstring). Every constant is float32, so
    that a loop around it stays float32.
    """
    # NaN fails every comparison: x keeps it (and passes it to r below), t is clamped to a number
    xc = EXP_F32_MIN if x < EXP_F32_MIN else x
    t = -xc * LOG2E_F32 + _F32_HALF
    t = t if t < _F32_N_MAX else _F32_N_MAX  # also catches NaN, so that 2^-n is defined
    t = t if t > _F32_N_MIN else _F32_N_MIN
    n = np.floor(t)  # round(-x / ln 2), as a float32 (vroundps)
    r = (xc + n * LN2_HI_F32) + n * LN2_LO_F32  # x - (-n) ln 2, |r| <= ln 2 / 2
    # Estrin's scheme for sum_k r^k / k!, k = 1 .. 7, and the 1 added last: the terms from r on
    # are at most 0.42 and round to a quarter of the ulp of the result, where adding the 1 first
    # (1 + r) rounds to half of it (measured over 6e7 random x in [-87.3, 0]: at most 1.28
    # against 1.73 ulp)
    c = _F32_C
    r2 = r * r
    r4 = r2 * r2
    a23 = c[2] + r * c[3]
    a45 = c[4] + r * c[5]
    a67 = c[6] + r * c[7]
    p = c[0] + ((r + r2 * a23) + r4 * (a45 + r2 * a67))
    e = p * _pow2_f32(-n)
    return _F32_ZERO if x < EXP_F32_MIN else e
