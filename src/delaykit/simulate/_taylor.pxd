# The C types of _taylor.py for Cython (the .py is the one source; see _poly.pxd).  The kernel is built with them (setup.py's FUSED).
cimport cython

cdef Py_ssize_t _LIN, _HIGH, _LOW, _DEG, _NC
cdef Py_ssize_t _UMIN, _UMAX, _DY, _DYD, _DVR, _DVY, _DVV, _INTEG, _AW

@cython.locals(i=Py_ssize_t)
cpdef bint _vanished(double[:, :] X, Py_ssize_t N, Py_ssize_t j) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t)
cpdef void _clear_tail(double[:, :] X, double[:] Y, double[:] Yd, double[:] V, double[:] E, Py_ssize_t N,
                       Py_ssize_t nt, Py_ssize_t nz) noexcept nogil
cpdef void _hold_at_limit(double[:, :] X, double[:] V, double[:, :] VE, Py_ssize_t integ, Py_ssize_t j,
                          double lim, double[:] Fz) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef (double, double, double) _state_parts(double[:, :] X, double[:, :] VE, Py_ssize_t N,
                                            Py_ssize_t j, bint need_yd) noexcept nogil
cpdef (double, double, double) _signals(Py_ssize_t j, double cy, double cyd, double cv, double wj, double rj,
                                        bint yd_on, bint law_on, double vj, bint use_meas, double[:] Ym,
                                        double[:] Vm, double dy, double dyd, double dvr, double dvy,
                                        double dvv, double[:] Y, double[:] Yd, double[:] V,
                                        double[:] E) noexcept nogil
@cython.locals(j=Py_ssize_t, hold=bint)
cpdef Py_ssize_t _known_one(double[:, :] A, double[:, :] G, double[:, :] VE, double H,
                            bint frozen, Py_ssize_t integ, double w0, double[:] Wd, Py_ssize_t nW,
                            double[:] R, Py_ssize_t nR, double[:] Ym, double[:] Vm, bint use_meas,
                            bint need_yd, double[:] d5, double[:, :] X, double[:] Y, double[:] Yd, double[:] V,
                            double[:] E, bint zero_a, Py_ssize_t nf, Py_ssize_t nz) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t)
cpdef Py_ssize_t recursion_known(double[:, :] A, double[:, :] G, double[:, :] VE, Py_ssize_t N,
                                 double H, bint frozen, Py_ssize_t integ, double w0, double[:] Wd,
                                 Py_ssize_t nW, double[:] R, Py_ssize_t nR, double[:] Ym,
                                 double[:] Vm, bint use_meas, bint need_yd, double[:] d5,
                                 double[:, :] X, double[:] Y, double[:] Yd, double[:] V, double[:] E, bint zero_a,
                                 bint slide, double lim, double[:] Fz, Py_ssize_t nz) noexcept nogil
@cython.locals(j=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t, integ=Py_ssize_t, aw=Py_ssize_t)
cpdef Py_ssize_t recursion(double[:] par, double[:, :] Mloc, double[:, :] VE, Py_ssize_t N,
                           double H, Py_ssize_t regime, bint frozen, bint algebraic, bint ti_pos, bint sampled,
                           double uhold, double dist, double[:, :] X, double[:] R, Py_ssize_t nR,
                           double[:] Wd, Py_ssize_t nW, double[:] Ym, double[:] Vm, bint use_meas,
                           double[:] Y, double[:] Yd, double[:] V, double[:] E, bint need_yd, double[:] Um,
                           Py_ssize_t nUm, bint has_u, bint slide, double[:] Fz, Py_ssize_t nz) noexcept nogil
