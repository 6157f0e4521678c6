# The C types of _discretekernel.py for Cython (the .py stays the one source; see spectrum/_rootkernel.pxd).
cimport cython

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t)
cpdef void aug_expm(const double[:, :] A, const double[:] B, double t, double[:, :] E, double[:, :] X,
                    double[:, :] T, double[:, :] W) noexcept nogil

@cython.locals(n=Py_ssize_t, phi="double[:, ::1]", g="double[:, ::1]", work="double[:, :, ::1]")
cpdef held_arrays(const double[:, :] A, const double[:] B, double h, double f)

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, k=Py_ssize_t, acc=double, Er="double[:, :]",
               Ef="double[:, :]")
cpdef void held_arrays_into(const double[:, :] A, const double[:] B, double h, double f, double[:, :] phi,
                            double[:] ge, double[:] gl, double[:, :, :] work) noexcept nogil

@cython.locals(n=Py_ssize_t, N=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t, q=Py_ssize_t, lag_now=Py_ssize_t,
               j=Py_ssize_t, je=Py_ssize_t, jl=Py_ssize_t, u_now=double, yk=double, dk=double, uk=double, ue=double,
               ul=double, s=double)
cpdef void run_into(const double[:, :] phi, const double[:] g_early, const double[:] g_late, const double[:] c,
                    double d, const double[:] ca, double cb, Py_ssize_t m, bint fractional, const double[:] drive,
                    bint closed, double kp, double kv, double lo, double hi, double[:] y, double[:] dy, double[:] u,
                    double[:] x, double[:] xn) noexcept nogil

@cython.locals(N=Py_ssize_t, n=Py_ssize_t, u="double[::1]", y="double[::1]", dy="double[::1]", x="double[::1]",
               xn="double[::1]")
cpdef run(const double[:, :] phi, const double[:] g_early, const double[:] g_late, const double[:] c, double d,
          const double[:] ca, double cb, Py_ssize_t m, bint fractional, const double[:] drive, bint closed, double kp,
          double kv, double lo, double hi)

@cython.locals(n=Py_ssize_t, x="double[::1]", xn="double[::1]", u="double[::1]")
cpdef void run_logs(const double[:, :] phi, const double[:] g_early, const double[:] g_late, const double[:] c,
                    double d, const double[:] ca, double cb, Py_ssize_t m, bint fractional, const double[:] drive,
                    const long long[:] starts, bint closed, double kp, double kv, const double[:] lo,
                    const double[:] hi, bint unit, double[:] y, double[:] dy, double[:] uy, double[:] udy)

@cython.locals(i=Py_ssize_t, k=Py_ssize_t, a=Py_ssize_t, b=Py_ssize_t)
cpdef void run_logs_into(const double[:, :] phi, const double[:] g_early, const double[:] g_late,
                         const double[:] c, double d, const double[:] ca, double cb, Py_ssize_t m, bint fractional,
                         const double[:] drive, const long long[:] starts, bint closed, double kp, double kv,
                         const double[:] lo, const double[:] hi, bint unit, double[:] y, double[:] dy,
                         double[:] uy, double[:] udy, double[:] u, double[:] x, double[:] xn) noexcept nogil

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, q=Py_ssize_t, s=double)
cpdef void advance(const double[:, :] A, const double[:] B, double dt, double v, double[:] x, double[:] xn,
                   double[:, :] E, double[:, :] X, double[:, :] T, double[:, :] W) noexcept nogil

@cython.locals(n=Py_ssize_t, N=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, q=Py_ssize_t, x="double[::1]",
               xn="double[::1]", E="double[:, ::1]", X="double[:, ::1]", T="double[:, ::1]", W="double[:, ::1]",
               tau=double, v=double, s=double, yk=double, dk=double)
cpdef void run_at_into(const double[:, :] A, const double[:] B, const double[:] c, double d, const double[:] ca,
                       double cb, double delay, double tol, const double[:] t, const double[:] drive, double[:] y,
                       double[:] dy)

@cython.locals(i=Py_ssize_t, a=Py_ssize_t, b=Py_ssize_t, ones="double[::1]")
cpdef void run_at_logs(const double[:, :] A, const double[:] B, const double[:] c, double d, const double[:] ca,
                       double cb, double delay, double tol, const double[:] t, const double[:] drive,
                       const long long[:] starts, bint unit, double[:] y, double[:] dy, double[:] uy, double[:] udy)
