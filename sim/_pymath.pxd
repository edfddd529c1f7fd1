# Python's own float arithmetic where it is not the C library's: the compiled core must give the
# bits the pure-Python reference gives (sim/compiled.py).
from libc.math cimport fabs, fmod, copysign


cdef inline double py_mod(double a, double b) noexcept:
    """Python's ``a % b`` on floats (float_rem): the remainder takes the sign of ``b``."""
    cdef double m = fmod(a, b)
    if m:
        if (b < 0) != (m < 0):
            m += b
    else:
        m = copysign(0.0, b)
    return m


cdef inline double py_remainder(double x, double y) noexcept:
    """Python's ``math.remainder`` (m_remainder) for finite x and y != 0: exact, as IEEE's."""
    cdef double absx = fabs(x), absy = fabs(y)
    cdef double m = fmod(absx, absy)
    cdef double c = absy - m
    cdef double r
    if m < c:
        r = m
    elif m > c:
        r = -c
    else:
        r = m - 2.0 * fmod(0.5 * (absx - m), absy)
    return copysign(1.0, x) * r


cdef inline double py_max(double a, double b) noexcept:
    """Python's ``max(a, b)``: ``a`` unless ``b`` is greater (keeps a -0.0 or a NaN ``a``)."""
    return b if b > a else a


cdef inline double py_min(double a, double b) noexcept:
    """Python's ``min(a, b)``: ``a`` unless ``b`` is less."""
    return b if b < a else a
