"""log, exp and x**y in plain arithmetic, so that loops calling them vectorise.

The contact kernel needs zeta**(1 - p) for thousands of pairs per evaluation
(docs/model.md §6). llvmlite here has no vector math library, so ``zeta ** e`` is one
scalar libm call per pair (~15 ns, ~40 % of a contact evaluation); these versions
are straight-line floating-point and integer code that LLVM turns into AVX2 loops.

Accuracy: ``log_pos`` and ``exp_finite`` are fdlibm's algorithms (e_log.c, e_exp.c:
the same reductions and minimax coefficients), each < 1 ulp. ``pow_pos(x, y)`` =
exp(y log x) is then accurate to (|y log x| + 1) ulp relative, e.g. <= 2e-15 for
zeta >= 1e-5 and p = 2.4; ``tests/test_elementary.py`` measures it against libm.

Domain (the caller's duty, no checks on the hot path): ``log_pos`` needs a finite
normal x > 0 (x >= 2.2250738585072014e-308); ``exp_finite`` needs |y| <= 708 so
that 2**k stays a normal number. Do not compile these with ``fastmath``: the
round-to-integer trick ``(v + 1.5 * 2**52) - 1.5 * 2**52`` relies on IEEE rounding.
"""

from __future__ import annotations

from numba import njit, types
from numba.extending import intrinsic

_LN2_HI = 6.93147180369123816490e-01  # upper bits of log(2), exact times small ints
_LN2_LO = 1.90821492927058770002e-10
_INV_LN2 = 1.44269504088896338700e00
_SQRT2 = 1.4142135623730951
_ROUND = 6755399441055744.0  # 1.5 * 2**52: adding it rounds to an integer
_ROUND_BITS = 0x4338000000000000

# fdlibm e_log.c: log(1+f) = f - hfsq + s (hfsq + R(s^2)), s = f/(2+f)
_LG1 = 6.666666666666735130e-01
_LG2 = 3.999999999940941908e-01
_LG3 = 2.857142874366239149e-01
_LG4 = 2.222219843214978396e-01
_LG5 = 1.818357216161805012e-01
_LG6 = 1.531383769920937332e-01
_LG7 = 1.479819860511658591e-01

# fdlibm e_exp.c: exp(r) = 1 + 2r/(2 - c), c = r - r^2 P(r^2)
_P1 = 1.66666666666666019037e-01
_P2 = -2.77777777770155933842e-03
_P3 = 6.61375632143793436117e-05
_P4 = -1.65339022054652515390e-06
_P5 = 4.13813679705723846039e-08

_MANT_MASK = 0x000FFFFFFFFFFFFF
_ONE_BITS = 0x3FF0000000000000


@intrinsic
def _bits(typingctx, x):
    """The IEEE-754 bit pattern of a float64 as an int64 (a register bitcast)."""
    if x != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.int64))

    return types.int64(types.float64), codegen


@intrinsic
def _from_bits(typingctx, b):
    """The float64 whose bit pattern is the int64 ``b``."""
    if b != types.int64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], context.get_value_type(types.float64))

    return types.float64(types.int64), codegen


@njit(cache=True, inline="always")
def log_pos(x):
    """Natural logarithm of a finite, normal x > 0 (fdlibm ``__ieee754_log``)."""
    b = _bits(x)
    k = (b >> 52) - 1023
    m = _from_bits((b & _MANT_MASK) | _ONE_BITS)  # x = m 2^k, m in [1, 2)
    big = m > _SQRT2
    m = m * 0.5 if big else m  # m in [sqrt(2)/2, sqrt(2)): |f| <= 0.415
    k = k + 1 if big else k
    f = m - 1.0  # exact (Sterbenz)
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (_LG2 + w * (_LG4 + w * _LG6))
    t2 = z * (_LG1 + w * (_LG3 + w * (_LG5 + w * _LG7)))
    r = t2 + t1
    hfsq = 0.5 * f * f
    dk = _from_bits(k + _ROUND_BITS) - _ROUND  # float(k), in vectorisable form
    return dk * _LN2_HI - ((hfsq - (s * (hfsq + r) + dk * _LN2_LO)) - f)


@njit(cache=True, inline="always")
def exp_finite(y):
    """e**y for |y| <= 708 (fdlibm ``__ieee754_exp``)."""
    t = y * _INV_LN2 + _ROUND
    k = _bits(t) - _ROUND_BITS  # round(y / ln 2) as an integer
    dk = t - _ROUND  # the same integer as a float
    hi = y - dk * _LN2_HI
    lo = dk * _LN2_LO
    r = hi - lo
    rr = r * r
    c = r - rr * (_P1 + rr * (_P2 + rr * (_P3 + rr * (_P4 + rr * _P5))))
    e = 1.0 - ((lo - (r * c) / (2.0 - c)) - hi)
    return e * _from_bits((k + 1023) << 52)


@njit(cache=True, inline="always")
def pow_pos(x, y):
    """x**y = exp(y log x) for normal x > 0 and |y log x| <= 708."""
    return exp_finite(y * log_pos(x))
