# The C types of _rootkernel.py for Cython: the .py stays the one source (run by Python or numba as it is); this
# file only declares what each name is when Cython compiles it to an extension module at build time (setup.py:
# no bounds or negative-index checks, as numba).
cimport cython

cdef double _EPS

@cython.locals(r=double)
cdef double complex cexp(double complex z) noexcept nogil
cdef double complex clog(double complex z) noexcept nogil
cdef double _ipow(double a, Py_ssize_t n) noexcept nogil

@cython.locals(nt=Py_ssize_t, n1=Py_ssize_t, j=Py_ssize_t, k=Py_ssize_t, Q="double complex", dQ="double complex",
               nz=double, abs_s=double, p="double complex", dp="double complex", pa=double, e="double complex")
cdef (double complex, double complex, double) qeval(const double complex[:, :] C, const double[:, :] A,
                                                   const double[:] tau, double complex s) noexcept nogil

@cython.locals(size=Py_ssize_t, e=Py_ssize_t)
cpdef Py_ssize_t stack_size(const long long[:] n_init) noexcept nogil

cpdef tuple stacks(Py_ssize_t size)

@cython.locals(sa="double complex[::1]", sb="double complex[::1]", wa="double complex[::1]",
               wb="double complex[::1]", ra="double[::1]", rb="double[::1]")
cpdef contour(const double complex[:, :] C, const double[:, :] A, const double[:] tau,
              const double complex[:] corners, const long long[:] n_init, double max_phase, double reliable,
              Py_ssize_t cap, double complex[:] out_s, double complex[:] out_dl)

@cython.locals(nc=Py_ssize_t, total=double, m=Py_ssize_t, size=Py_ssize_t, e=Py_ssize_t, n=Py_ssize_t,
               top=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t,
               a0="double complex", b0="double complex", prev_s="double complex", prev_w="double complex",
               prev_r=double, Qp="double complex", dQp="double complex", nzp=double,
               s0="double complex", Q0="double complex", dQ0="double complex", nz0=double,
               a="double complex", b="double complex", qa="double complex", qb="double complex", r_a=double,
               r_b=double, dl="double complex", h=double, need=double,
               nxt_s="double complex", nxt_w="double complex", nxt_r=double,
               si="double complex", Qi="double complex", dQi="double complex", nzi=double, ri=double)
cpdef (int, double, Py_ssize_t, double complex) contour_into(
    const double complex[:, :] C, const double[:, :] A, const double[:] tau, const double complex[:] corners,
    const long long[:] n_init, double max_phase, double reliable, Py_ssize_t cap, double complex[:] out_s,
    double complex[:] out_dl, double complex[:] sa, double complex[:] sb, double complex[:] wa, double complex[:] wb,
    double[:] ra, double[:] rb) noexcept nogil

@cython.locals(n=Py_ssize_t, out="double complex[::1]", conv="unsigned char[::1]", clean="unsigned char[::1]")
cpdef newton(const double complex[:, :] C, const double[:, :] A, const double[:] tau, const double complex[:] s0,
             Py_ssize_t maxit, const double[:] box)

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, x0=double, x1=double, y0=double, y1=double, s="double complex",
               Q="double complex", dQ="double complex", nz=double, step="double complex")
cpdef void newton_into(const double complex[:, :] C, const double[:, :] A, const double[:] tau,
                       const double complex[:] s0, Py_ssize_t maxit, const double[:] box, double complex[:] out,
                       unsigned char[:] conv, unsigned char[:] clean) noexcept nogil

@cython.locals(nx=Py_ssize_t, ny=Py_ssize_t, nt=Py_ssize_t, n1=Py_ssize_t, j=Py_ssize_t, k=Py_ssize_t,
               ix=Py_ssize_t, iy=Py_ssize_t, di=Py_ssize_t, dj=Py_ssize_t, EX="double[:, ::1]",
               EY="double complex[:, ::1]", V="double[:, ::1]", out="double complex[::1]", s="double complex",
               Q="double complex", p="double complex", a=double, v=double, ok=bint)
cpdef grid_minima(const double complex[:, :] C, const double[:] tau, const double[:] xs, const double[:] ys)

@cython.locals(n1=Py_ssize_t)
cpdef double bound(const double complex[:, :] C, const double[:] tau, double x) except? -2.0

@cython.locals(nt=Py_ssize_t, n1=Py_ssize_t, j=Py_ssize_t, k=Py_ssize_t, k0=Py_ssize_t, g=double, lead=double,
               hi=double, lo=double, mid=double)
cpdef double bound_into(const double complex[:, :] C, const double[:] tau, double x, double complex[:] p0,
                        double[:] oth) noexcept nogil
