# The C types of _poly.py for Cython: the .py stays the one source (run by Python or numba as it is); this file
# declares what each name is when Cython compiles it at build time, and the kernels that call these functions
# cimport them from here (C calls; the Loop kernel is compiled with this file, setup.py's FUSED).  setup.py: no
# bounds or negative-index checks, C division, locals' types inferred (as numba does).
cimport cython

cdef Py_ssize_t _GRID, _DEPTH, _MAXX, _NC
cdef double[::1] _XG
cdef double[:, ::1] _BIN

@cython.locals(j=Py_ssize_t)
cpdef double horner(double[::1] c, Py_ssize_t n, double x) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef (double, double) horner_d(double[::1] c, Py_ssize_t n, double x) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef double poly_sum(double[::1] c, Py_ssize_t n) noexcept nogil
@cython.locals(j=Py_ssize_t, cj=double, p=double)
cpdef (double, double, double) bounds(double[::1] c, Py_ssize_t n) noexcept nogil
cpdef double refine(double[::1] c, Py_ssize_t n, double target, double lo, double hi, double slo) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef void grid_values(double[::1] c, Py_ssize_t n, double target, double[::1] fs, Py_ssize_t i0) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef double first_cross(double[::1] c, Py_ssize_t n, double target, double s0, double[::1] fs) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef Py_ssize_t all_cross(double[::1] c, Py_ssize_t n, double target, double[::1] xs, double[::1] fs) noexcept nogil
@cython.locals(i=Py_ssize_t, b1=double, b2=double, size=double, noise=double, top=Py_ssize_t, j=Py_ssize_t,
               k=Py_ssize_t, d=Py_ssize_t, xl=double, fl=double, sl=double, r=double, fr=double, w=double,
               change=bint, ok=bint)
cpdef Py_ssize_t crossings(double[::1] c, Py_ssize_t n, double target, double[::1] xs, double[::1] sr,
                           long long[::1] sd) noexcept nogil
@cython.locals(k=Py_ssize_t, j=Py_ssize_t)
cpdef void shift_scale(double[::1] src, Py_ssize_t n, double alpha, double beta, double[::1] dst,
                       double[::1] work) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef void scale(double[::1] c, Py_ssize_t n, double s) noexcept nogil
cpdef Py_ssize_t degree(double[::1] c, Py_ssize_t n) noexcept nogil
