# The C types of _taylor.py for Cython (the .py is the one source; see _poly.pxd).  The kernel is built with them (setup.py's FUSED).
cimport cython

cdef Py_ssize_t _LIN, _HIGH, _LOW, _DEG, _NC
cdef Py_ssize_t _UMIN, _UMAX, _DY, _DYD, _DVR, _DVY, _DVV, _INTEG, _AW

@cython.locals(i=Py_ssize_t)
cpdef bint _vanished(double[:, ::1] X, Py_ssize_t N, Py_ssize_t j) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t)
cpdef void _clear_tail(double[:, ::1] X, double[::1] Y, double[::1] Yd, double[::1] V, double[::1] E, Py_ssize_t N,
                       Py_ssize_t nt, Py_ssize_t nz) noexcept nogil
cpdef void _hold_at_limit(double[:, ::1] X, double[::1] V, double[:, ::1] VE, Py_ssize_t integ, Py_ssize_t j,
                          double lim, double[::1] Fz) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef (double, double, double) _state_parts(double[:, ::1] X, double[:, ::1] VE, Py_ssize_t N,
                                            Py_ssize_t j, bint need_yd) noexcept nogil
cpdef (double, double, double) _signals(Py_ssize_t j, double cy, double cyd, double cv, double wj, double rj,
                                        bint yd_on, bint law_on, double vj, bint use_meas, double[::1] Ym,
                                        double[::1] Vm, double dy, double dyd, double dvr, double dvy,
                                        double dvv, double[::1] Y, double[::1] Yd, double[::1] V,
                                        double[::1] E) noexcept nogil
@cython.locals(j=Py_ssize_t, hold=bint)
cpdef Py_ssize_t _known_one(double[:, ::1] A, double[:, ::1] G, double[:, ::1] VE, double H, bint frozen,
                            Py_ssize_t integ, double w0, double[::1] Wd, Py_ssize_t nW, double[::1] R, Py_ssize_t nR,
                            double[::1] Ym, double[::1] Vm, bint use_meas, bint need_yd, double[::1] d5,
                            double[:, ::1] X, double[::1] Y, double[::1] Yd, double[::1] V, double[::1] E, bint zero_a,
                            Py_ssize_t nf, Py_ssize_t nz) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t)
cpdef Py_ssize_t recursion_known(double[:, ::1] A, double[:, ::1] G, double[:, ::1] VE, Py_ssize_t N, double H,
                                 bint frozen, Py_ssize_t integ, double w0, double[::1] Wd, Py_ssize_t nW, double[::1] R,
                                 Py_ssize_t nR, double[::1] Ym, double[::1] Vm, bint use_meas, bint need_yd,
                                 double[::1] d5, double[:, ::1] X, double[::1] Y, double[::1] Yd, double[::1] V,
                                 double[::1] E, bint zero_a, bint slide, double lim, double[::1] Fz,
                                 Py_ssize_t nz) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t, integ=Py_ssize_t, aw=Py_ssize_t)
cpdef Py_ssize_t recursion(double[::1] par, double[:, ::1] Mloc, double[:, ::1] VE, Py_ssize_t N,
                           double H, Py_ssize_t regime, bint frozen, bint algebraic, bint ti_pos, bint sampled,
                           double uhold, double dist, double[:, ::1] X, double[::1] R, Py_ssize_t nR,
                           double[::1] Wd, Py_ssize_t nW, double[::1] Ym, double[::1] Vm, bint use_meas,
                           double[::1] Y, double[::1] Yd, double[::1] V, double[::1] E, bint need_yd, double[::1] Um,
                           Py_ssize_t nUm, bint has_u, bint slide, double[::1] Fz,
                           Py_ssize_t nz) noexcept nogil
