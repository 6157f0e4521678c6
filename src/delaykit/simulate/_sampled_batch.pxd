# The C types of _sampled_batch.py for Cython (the .py is the one source; see _poly.pxd).  Every run works in the
# caller's arrays, without the GIL; run_batch's loop over work sets runs in parallel (OpenMP, where setup.py found it).
cimport cython

ctypedef (double, double, double, double, double) metrics5

cdef Py_ssize_t DEG, MAXN, NC, NOUT, OFF_BR, OFF_CY, OFF_M
cdef double STATUS_OK, _INF, _NAN, _GMAX_BETA, _SUB_BETA, _REM, _MARGIN
cdef Py_ssize_t _MAXX, _STACK, _NSLOT, _NA, _NQ, _SA, _SS, _GKEEP, _WMAX, _TPEAK, _T10, _T90, _TLAST
cdef Py_ssize_t _N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD
cdef Py_ssize_t _DVR, _DVY, _DVV, _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM

cpdef void _poly_metrics(double[::1] Wn, Py_ssize_t nW, double a, double H, double band, double[::1] ms, double[::1] dW,
                         double[::1] xs, double[::1] sr, long long[::1] sd) noexcept nogil
@cython.locals(i=Py_ssize_t, sub=Py_ssize_t, k=Py_ssize_t, j=Py_ssize_t, nsub=Py_ssize_t, nt=Py_ssize_t)
cpdef double _expand(double[:] zs, double[:, :] Zs, double[:] cs, Py_ssize_t ns, double tau, double a, double inv,
                     double ref, double band, double[::1] ms, double[:] q, double[:] qn, double[:] zsum, double[:] Y,
                     double[::1] Wn, double[::1] dW, double[::1] xs, double[::1] sr, long long[::1] sd) noexcept nogil
# the three helpers of every interval, inline as numba's (NUMBA_OPTIONS); gcc did not inline _interval_metrics (15 %
# of the batch's time in perf), whose tuple of running metrics then went in and out by value
cdef inline double _row4(double[:, :, :] M, Py_ssize_t s, Py_ssize_t r, double z0, double z1, double z2,
                         double z3) noexcept nogil
cdef inline double _slope_bound(double[:, :] G, unsigned char[:] cheap, Py_ssize_t s, double v0,
                                double v1) noexcept nogil
@cython.locals(w1out=bint, peak=bint, bchk=bint, open10=bint, open90=bint, mono=bint, need=bint)
cdef inline (metrics5, double, bint) _interval_metrics(double y0, double y1, double d1, double gs, double a,
                                                      double end, metrics5 st, double inv, double ainv,
                                                      double band) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef (metrics5, double) _expanded(metrics5 st, double[:, :] src, Py_ssize_t row, Py_ssize_t ns, double tau, double a,
                                   double inv, double ref, double band, double[::1] ms, double[:, :] Zs, double[:] cs,
                                   double[:] zs, double[:] q, double[:] qn, double[:] zsum, double[:] Y,
                                   double[::1] Wn, double[::1] dW, double[::1] xs, double[::1] sr,
                                   long long[::1] sd) noexcept nogil
@cython.locals(i=Py_ssize_t, d=Py_ssize_t, m=Py_ssize_t, k=Py_ssize_t, j=Py_ssize_t, s=double, r=Py_ssize_t)
cpdef void _pair(double[:, :, :] Q, Py_ssize_t sa, Py_ssize_t sb, double tau_a, Py_ssize_t N, long long[:] dpos,
                 Py_ssize_t pw, Py_ssize_t pr, Py_ssize_t prs, Py_ssize_t ns, double[:, :] EA, double[:, :] Pab,
                 double[:] gb, double[:, :] Es, double[:, :] Rb, double[:] Rbw) noexcept nogil
@cython.locals(i=Py_ssize_t, r=Py_ssize_t, d=Py_ssize_t, k=Py_ssize_t, j=Py_ssize_t, l=Py_ssize_t, rho='double[:]',
               rn='double[:]', g='double[:]')
cpdef double _fill_slot(double[:, :] Z, Py_ssize_t na, Py_ssize_t N, double tau, long long[:] dpos, Py_ssize_t ns,
                        double[:] cs, long long[:] rows, Py_ssize_t nrow, bint metrics, Py_ssize_t slot,
                        double[:, :, :] Q, double[:, :] G, double[:, :] A, double[:, :] E, double[:, :] T,
                        double[:, :] W, double[:, :] gw) noexcept nogil
@cython.locals(i=Py_ssize_t, s=Py_ssize_t, k=Py_ssize_t, j=Py_ssize_t, d=Py_ssize_t, r=Py_ssize_t, N=Py_ssize_t,
               na=Py_ssize_t, iw=Py_ssize_t, ir=Py_ssize_t, irs=Py_ssize_t, ns=Py_ssize_t, nrow=Py_ssize_t,
               nq=Py_ssize_t, nring=Py_ssize_t, nslot=Py_ssize_t, pw=Py_ssize_t, pr=Py_ssize_t, prs=Py_ssize_t,
               pair_a=Py_ssize_t, pair_b=Py_ssize_t, ks=Py_ssize_t, kput=Py_ssize_t, ki=Py_ssize_t, kget=Py_ssize_t,
               n=Py_ssize_t, slot=Py_ssize_t, slot_prev=Py_ssize_t, cur=Py_ssize_t, nxt=Py_ssize_t, sa=Py_ssize_t,
               sb=Py_ssize_t, s_new=Py_ssize_t, metrics=bint, has_dist=bint, grew=bint, small=bint, sampled=bint,
               dist_on=bint, need=bint, nz=bint, st='metrics5', c0='double[:]', k0='double[:]', c='double[:]',
               kv='double[:]', cs='double[:]', seen='unsigned char[:]', cheap='unsigned char[:]',
               perm='long long[:]', pos='long long[:]', dpos='long long[:]',
               rows='long long[:]', sm=double)
cpdef Py_ssize_t run_one(double[:] par, double[::1] out, double[:, :] Z, double[:, :, :] Q, double[:, :] G,
                         double[:] taus, double[:, :] A, double[:, :] E, double[:, :] T, double[:, :] W,
                         double[:, :] zb, double[:] acc, double[:] zs, double[:, :] Zs, double[:] q, double[:] qn,
                         double[:] zsum, double[:] Y, double[::1] Wn, double[::1] dW, double[::1] xs, double[::1] sr,
                         long long[::1] sd, double[::1] ms, double[:, :] EA, double[:, :] Pab, double[:] gb,
                         double[:, :] Es, double[:, :] Rb, double[:] Rbw, double[:, :] zi, double[:, :] Z0,
                         double[:, :] vec, double[:] ring, unsigned char[:, :] flags, long long[:, :] idx,
                         long long[:] used, double[:, :] gw) noexcept nogil
@cython.locals(i=Py_ssize_t, m=Py_ssize_t, nring=Py_ssize_t)
cpdef run_batch(double[:, :] pars, Py_ssize_t nchunks, Py_ssize_t nsets=*)
@cython.locals(s=Py_ssize_t)
cpdef void _batch_sets(double[:, :] pars, Py_ssize_t nchunks, Py_ssize_t nsets, double[:, ::1] out, double[:, :, :] Z,
                       double[:, :, :, :] Q, double[:, :, :] G, double[:, :] taus, double[:, :, :] A, double[:, :, :] E,
                       double[:, :, :] T, double[:, :, :] W, double[:, :, :] zb, double[:, :] acc, double[:, :] zs,
                       double[:, :, :] Zs, double[:, :] q, double[:, :] qn, double[:, :] zsum, double[:, :] Y,
                       double[:, ::1] Wn, double[:, ::1] dW, double[:, ::1] xs, double[:, ::1] sr, long long[:, ::1] sd,
                       double[:, ::1] ms, double[:, :, :] EA, double[:, :, :] Pab, double[:, :] gb, double[:, :, :] Es,
                       double[:, :, :] Rb, double[:, :] Rbw, double[:, :, :] zi, double[:, :, :] Z0,
                       double[:, :, :] vec, double[:, :] ring, unsigned char[:, :, :] flags, long long[:, :, :] idx,
                       long long[:, :] used, double[:, :, :] gw) noexcept nogil
@cython.locals(k=Py_ssize_t, i=Py_ssize_t, m=Py_ssize_t, lo=Py_ssize_t, hi=Py_ssize_t)
cpdef void _set_chunks(double[:, :] pars, Py_ssize_t nchunks, Py_ssize_t nsets, Py_ssize_t s, double[:, ::1] out,
                       double[:, :] Z, double[:, :, :] Q, double[:, :] G, double[:] taus, double[:, :] A,
                       double[:, :] E, double[:, :] T, double[:, :] W, double[:, :] zb, double[:] acc, double[:] zs,
                       double[:, :] Zs, double[:] q, double[:] qn, double[:] zsum, double[:] Y, double[::1] Wn,
                       double[::1] dW, double[::1] xs, double[::1] sr, long long[::1] sd, double[::1] ms,
                       double[:, :] EA, double[:, :] Pab, double[:] gb, double[:, :] Es, double[:, :] Rb, double[:] Rbw,
                       double[:, :] zi, double[:, :] Z0, double[:, :] vec, double[:] ring, unsigned char[:, :] flags,
                       long long[:, :] idx, long long[:] used, double[:, :] gw) noexcept nogil
