# The C types of _ltikernel.py for Cython: the .py stays the one source (run by Python or numba as it is); this
# file only declares what each name is when Cython compiles it to an extension module at build time (setup.py:
# no bounds or negative-index checks, as numba).
cimport cython

cdef Py_ssize_t _DEG, _NC, _OK, _CAPACITY, _STALLED, _OVERFLOW, _LIN, _HIGH, _LOW, _GRIDN, _MODE_TRIES, _PICARD
cdef Py_ssize_t _NGROW
cdef double _NAN, _EPS, _JUMP, _TRUNC, _FLOOR, _GROW, _SELF, _PICARD_TOL

@cython.locals(i=Py_ssize_t, j=Py_ssize_t, b=double)
cdef void _shift_scale(const double[:] src, Py_ssize_t n, double alpha, double beta, double[:] dst,
                       double[:] work) noexcept nogil

@cython.locals(s=double, j=Py_ssize_t)
cdef double _horner(const double[:] c, Py_ssize_t n, double x) noexcept nogil

@cython.locals(s=double, j=Py_ssize_t)
cdef double _horner_d(const double[:] c, Py_ssize_t n, double x) noexcept nogil

@cython.locals(sgn=double, prev=double, x=double, f=double, lo=double, hi=double, mid=double, g=Py_ssize_t,
               it=Py_ssize_t)
cdef double _first_exit(const double[:] c, Py_ssize_t n, double level, bint up, double x0) noexcept nogil

@cython.locals(k=Py_ssize_t)
cdef bint _add_bp(double[:, :] bp_t, long long[:, :] bp_o, long long[:] bp_n, Py_ssize_t c, double t,
                  long long order, double tol) noexcept nogil

@cython.locals(i=Py_ssize_t, j=Py_ssize_t, b=double)
cdef void _cut(double[:, :] P, Py_ssize_t rows, double xc, Py_ssize_t nc) noexcept nogil

@cython.locals(w0=Py_ssize_t, i=Py_ssize_t, k=Py_ssize_t, c=Py_ssize_t, o=Py_ssize_t, q=Py_ssize_t, s=double,
               f=double, j=Py_ssize_t, nc=Py_ssize_t, kc=Py_ssize_t, wbig=double, wn=double,
               p2=double, a2=double, g2=double, xs=double, ek=double)
cdef Py_ssize_t _recursion(const long long[:] gp, const long long[:] gi, const double[:] gv, const long long[:] hp,
                     const long long[:] hi_, const double[:] hv, const long long[:] jp, const long long[:] ji,
                     const double[:] jv, Py_ssize_t n, Py_ssize_t nu, Py_ssize_t m, Py_ssize_t ny,
                     const double[:] tau, const double[:] lo, const double[:] hi, const long long[:] mode,
                     const double[:] xa, double[:, ::1] S, double[:, ::1] Z, double[:, ::1] V, double[:, ::1] Y,
                     double H, double anorm, double bw, const double[:] iw, double[:] ws) noexcept nogil

@cython.locals(n=Py_ssize_t, nu=Py_ssize_t, m=Py_ssize_t, ny=Py_ssize_t, nt=Py_ssize_t, nk=Py_ssize_t,
               cap=Py_ssize_t, jcap=Py_ssize_t,
               X="double[:, ::1]", U="double[:, ::1]", W="double[:, ::1]", Z="double[:, ::1]", V="double[:, ::1]",
               Y="double[:, ::1]", SW="double[:, ::1]", Yprev="double[::1]", xa="double[::1]", work="double[::1]",
               tmp="double[::1]",
               work2="double[::1]", scale="double[::1]", mode="long long[::1]", rd="long long[::1]",
               ip="long long[::1]", border="long long[::1]", selfr="long long[::1]", wsum="double[::1]",
               i=Py_ssize_t, c=Py_ssize_t, l=Py_ssize_t, j=Py_ssize_t, d=Py_ssize_t, o=Py_ssize_t, k0=Py_ssize_t,
               q=Py_ssize_t, kq=Py_ssize_t, kn=Py_ssize_t, pieces=Py_ssize_t, njump=Py_ssize_t, status=Py_ssize_t,
               tries=Py_ssize_t, cfirst=Py_ssize_t, nxt=Py_ssize_t, to=Py_ssize_t, switched=Py_ssize_t,
               oc=Py_ssize_t, nc=Py_ssize_t, nq=Py_ssize_t,
               a=double, e=double, H=double, hcap=double, s=double, lim=double, slope=double, alpha=double,
               beta=double, z0=double, xcut=double, xs=double, x2=double, tl=double, big=double, L=double,
               jmax=double, hl=double, r=double, jm=double, dj=double, yscale=double, b=double, x=double,
               s1=double, s0=double, diff=double, sweep=Py_ssize_t, it=Py_ssize_t, settled=bint, last=bint,
               finite=bint, keep=bint, over=bint, anyself=bint, converged=bint, picard_failed=bint)
cdef void _core(const double[:, ::1] A, const double[:, ::1] B1, const double[:, ::1] B2, const double[:, ::1] C1,
          const double[:, ::1] C2, const double[:, ::1] D11, const double[:, ::1] D12, const double[:, ::1] D21,
          const double[:, ::1] D22, const long long[:] gp, const long long[:] gi, const double[:] gv,
          const long long[:] hp, const long long[:] hi_, const double[:] hv, const long long[:] jp,
          const long long[:] ji, const double[:] jv,
          const double[:] tau, const double[:] lo, const double[:] hi, const double[:] ut,
          const double[:, ::1] uv, const double[:] x0, const long long[:, :] Rw, const long long[:, :] Ru,
          const long long[:] R0, const double[:] tq, bint deriv, double t_end, double hmax, double anorm,
          double bw, const double[:] iw, double tol, double[:, :] out, double[:] hist_t, double[:] hist_h,
          long long[:] hist_n,
          double[:, :, ::1] hist_c, double[:, :] bp_t, long long[:, :] bp_o, long long[:] bp_n, double[:] jump_t,
          double[:, :] jump_v, double[:] info, double[:, ::1] FW, double[::1] F1, long long[::1] I1) noexcept nogil

@cython.locals(n=Py_ssize_t, nu=Py_ssize_t, m=Py_ssize_t, ny=Py_ssize_t, col=Py_ssize_t, rows=Py_ssize_t,
               nf=Py_ssize_t, ni=Py_ssize_t)
cpdef run(const double[:, ::1] A, const double[:, ::1] B1, const double[:, ::1] B2, const double[:, ::1] C1,
          const double[:, ::1] C2, const double[:, ::1] D11, const double[:, ::1] D12, const double[:, ::1] D21,
          const double[:, ::1] D22, const long long[:] gp, const long long[:] gi, const double[:] gv,
          const long long[:] hp, const long long[:] hi_, const double[:] hv, const long long[:] jp,
          const long long[:] ji, const double[:] jv,
          const double[:] tau, const double[:] lo, const double[:] hi, const double[:] ut,
          const double[:, :, ::1] uvs, const double[:] x0, const long long[:, :] Rw, const long long[:, :] Ru,
          const long long[:] R0, const double[:] tq, bint deriv, double t_end, double hmax, double anorm,
          double bw, const double[:] iw, double tol, double[:, :, :] out, double[:] hist_t, double[:] hist_h,
          long long[:] hist_n,
          double[:, :, ::1] hist_c, double[:, :] bp_t, long long[:, :] bp_o, long long[:] bp_n,
          double[:, :] jump_t, double[:, :, :] jump_v, double[:, :] info)

@cython.locals(njobs=Py_ssize_t, nu=Py_ssize_t, k=Py_ssize_t, tid=Py_ssize_t, sy=Py_ssize_t)
cpdef run_batch(const double[:, :, ::1] A, const double[:, :, ::1] B1, const double[:, :, ::1] B2,
                const double[:, :, ::1] C1, const double[:, :, ::1] C2, const double[:, :, ::1] D11,
                const double[:, :, ::1] D12, const double[:, :, ::1] D21, const double[:, :, ::1] D22,
                const long long[:, :] gp, const long long[:, :] gi, const double[:, :] gv, const long long[:, :] hp,
                const long long[:, :] hi_, const double[:, :] hv, const long long[:, :] jp, const long long[:, :] ji,
                const double[:, :] jv, const double[:, :] tau, const double[:, :] lo, const double[:, :] hi,
                const double[:] ut,
                const double[:, :, ::1] uvs, const double[:] x0, const long long[:, :, :] Rw,
                const long long[:, :, :] Ru, const long long[:] R0, const double[:] tq, bint deriv, double t_end,
                const double[:] hmax, const double[:] anorm, const double[:] bw,
                const double[:, :] iw, double tol, double[:, :, :] out,
                double[:, :] hist_t, double[:, :] hist_h, long long[:, :] hist_n, double[:, :, :, ::1] hist_c,
                double[:, :, :] bp_t, long long[:, :, :] bp_o, long long[:, :] bp_n,
                double[:, :] jump_t, double[:, :, :] jump_v, double[:, :] info, double[:, :, ::1] FW,
                double[:, ::1] F1, long long[:, ::1] I1)
