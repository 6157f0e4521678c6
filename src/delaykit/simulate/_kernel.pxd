# The C types of _kernel.py for Cython (the .py is the one source; see _poly.pxd).  The piece loop and its helpers
# run without the GIL; run_batch's loop over work sets runs in parallel (OpenMP, where setup.py found it).
cimport cython

cdef Py_ssize_t DEG, MAXN, NC, NOUT, OFF_BAW, OFF_BR, OFF_BU, OFF_BUM, OFF_BVM, OFF_BW, OFF_BYM, OFF_CV, OFF_CY
cdef Py_ssize_t OFF_CYD, OFF_M, _GRID, _LIN, _HIGH, _LOW
cdef double SELF, _GROW, STATUS_CAPACITY, STATUS_OK, STATUS_STALLED, _INF, _NAN
cdef double[:, ::1] _BIN
cdef Py_ssize_t _N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD
cdef Py_ssize_t _DVR, _DVY, _DVV, _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM
cdef Py_ssize_t _STALL, _NONE, _PICARD, _WMAX, _TPEAK, _T10, _T90, _TLAST, _WEND, _NMS, _NBUF, _PAD
cdef double _TAIL, _JUMP

@cython.locals(j=Py_ssize_t)
cpdef Py_ssize_t _classify(double[::1] V, Py_ssize_t n, double umin, double umax, double tol) noexcept nogil
cpdef Py_ssize_t _delayed(double[::1] t0, double[::1] th, double[:, ::1] tc, long long[::1] tdeg, Py_ssize_t q,
                          double s, double H, double[::1] dst, double[::1] work) noexcept nogil
cpdef Py_ssize_t _ref_poly(double[::1] rt, double[::1] r0, double[::1] rs, Py_ssize_t k, double a, double H,
                           double[::1] R) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef double _tail(double[:, ::1] X, Py_ssize_t N, double[::1] V, Py_ssize_t nt) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef double _last_ratio(double[::1] c) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef void _step_metrics(double[::1] Y, Py_ssize_t nY, double norm, double a, double H, double band, double[::1] ms,
                         double[::1] Wn, double[::1] dW, double[::1] xs, double[::1] fs,
                         long long[::1] sd) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef void _metrics_row(double[::1] out, bint metrics, double wmax, double wend, double tpeak, double t10, double t90,
                        double tlast, double norm, double band) noexcept nogil
@cython.locals(m=Py_ssize_t, j=Py_ssize_t, i=Py_ssize_t, idx=Py_ssize_t, k=Py_ssize_t)
cpdef void _metrics_update(double[::1] Wn, Py_ssize_t nW, double a, double H, double band, double[::1] ms,
                           double[::1] dW, double[::1] xs, double[::1] fs, double[::1] sr, long long[::1] sd,
                           bint certified) noexcept nogil
cpdef double _first_switch(double[::1] V, Py_ssize_t nv, double[::1] E, Py_ssize_t ne, Py_ssize_t regime, bint frozen,
                           double umin, double umax, Py_ssize_t aw, double[::1] fs) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef bint _continues(double[::1] t0, double[::1] th, double[:, ::1] tc, long long[::1] deg, bint full, Py_ssize_t n,
                      Py_ssize_t q, double s, double tol) noexcept nogil
cpdef Py_ssize_t _on_limit(double v0, double[::1] E, Py_ssize_t ne, double umin, double umax,
                           double tol) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef double _lead_sign(double[::1] c, Py_ssize_t n, double tol) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef Py_ssize_t _slide_rates(double[:, ::1] X, Py_ssize_t integ, double[::1] Fz, Py_ssize_t nt, double[::1] S,
                              double[::1] D) noexcept nogil
cpdef (Py_ssize_t, Py_ssize_t, double, Py_ssize_t) _image(double[::1] t0, signed char[::1] gen, Py_ssize_t n,
                                                          Py_ssize_t q, Py_ssize_t qg, double s, double a,
                                                          double delay, double eps) noexcept nogil
cpdef (Py_ssize_t, Py_ssize_t, double, Py_ssize_t, bint) _pending(double[::1] t0, signed char[::1] gen, Py_ssize_t n,
                                                                  Py_ssize_t q, Py_ssize_t qg, double s, double a,
                                                                  double delay, double eps,
                                                                  bint can_self) noexcept nogil
cpdef double _read_end(double[::1] t0, double[::1] th, double[:, ::1] tc, long long[::1] tdeg, bint full, Py_ssize_t n,
                       Py_ssize_t q, double delay, double end, double ctol) noexcept nogil
@cython.locals(i=Py_ssize_t, k=Py_ssize_t, m=Py_ssize_t)
cpdef Py_ssize_t _rel_degree(double[:, ::1] Mloc, double[:, ::1] VE, Py_ssize_t N, Py_ssize_t row_out,
                             Py_ssize_t row_in, Py_ssize_t k0, double[::1] v, double[::1] w) noexcept nogil
@cython.locals(j=Py_ssize_t, d=double, size=double, b=double, r=double, c=double)
cpdef (double, double) _jump(double[::1] cl, Py_ssize_t nl, double hl, double[::1] cr, Py_ssize_t nr, double hr,
                             double L, double[::1] tmp, double[::1] work) noexcept nogil
@cython.locals(k=Py_ssize_t, j=Py_ssize_t)
cpdef (double, Py_ssize_t) _picard(double[::1] src, Py_ssize_t n, double delta, double[::1] dst) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef Py_ssize_t _held(double[::1] c, Py_ssize_t n, double x, double[::1] dst) noexcept nogil
@cython.locals(X='double[:, ::1]', buf='double[::1]', mats='double[:, :, ::1]')
cpdef Py_ssize_t run_one(double[::1] par, double[::1] rt, double[::1] r0, double[::1] rs, Py_ssize_t cap,
                         double[::1] tu0, double[::1] thu, double[:, ::1] tuc, long long[::1] tdeg,
                         signed char[::1] ugen, double[::1] ty0, double[::1] tyh, double[:, ::1] tyc,
                         double[:, ::1] tyd, signed char[::1] ygen, double[::1] out, bint keep_y, double[::1] et,
                         double[::1] ez)
@cython.locals(i=Py_ssize_t, k=Py_ssize_t, j=Py_ssize_t, epsd=double, ytr=double, tiny_h=double, dl=double,
               N=Py_ssize_t, aw=Py_ssize_t, integ=Py_ssize_t, nref=Py_ssize_t, ne=Py_ssize_t, ke=Py_ssize_t,
               ksamp=Py_ssize_t, n=Py_ssize_t, nu=Py_ssize_t, ny=Py_ssize_t, qu=Py_ssize_t, qgu=Py_ssize_t,
               qy=Py_ssize_t, qgy=Py_ssize_t, qm=Py_ssize_t, qgm=Py_ssize_t, kr=Py_ssize_t, regime=Py_ssize_t,
               tiny=Py_ssize_t, ou=Py_ssize_t, oy=Py_ssize_t, gi_u=Py_ssize_t, gi_y=Py_ssize_t, gi_m=Py_ssize_t,
               nW=Py_ssize_t, nUm=Py_ssize_t, nR=Py_ssize_t, nt=Py_ssize_t, passes=Py_ssize_t, attempt=Py_ssize_t,
               keep_regime=Py_ssize_t, prev_regime=Py_ssize_t, side=Py_ssize_t, ns=Py_ssize_t, nv=Py_ssize_t,
               new=Py_ssize_t, nsrc=Py_ssize_t, nU=Py_ssize_t, nY=Py_ssize_t, o=Py_ssize_t, r_wy=Py_ssize_t,
               r_yu=Py_ssize_t, r_mu=Py_ssize_t, sampled=bint, cont=bint, ti_pos=bint, to_pos=bint, algebraic=bint,
               need_yd=bint, tm_pos=bint, switches=bint, has_dist=bint, metrics=bint, has_u=bint, nz=Py_ssize_t,
               regime_matters=bint,
               known=bint, slide_on=bint, neutral=bint, zero_a=bint, u_img=bint, y_img=bint, self_ok=bint, self_u=bint,
               self_y=bint, self_m=bint, self_any=bint, dist_on=bint, frozen=bint, sliding=bint, tried=bint,
               failed=bint, newf=bint, changed=bint, cut=bint, u_src=bint, y_src=bint, R='double[::1]',
               Wd='double[::1]', Um='double[::1]', Ym='double[::1]', Vm='double[::1]', Y='double[::1]',
               Yd='double[::1]', V='double[::1]', E='double[::1]', Wn='double[::1]', dW='double[::1]',
               work='double[::1]', Fz='double[::1]', S='double[::1]', D='double[::1]', xs='double[::1]',
               fs='double[::1]', x0='double[::1]', d5='double[::1]', ms='double[::1]', src='double[::1]',
               rv='double[::1]', rw='double[::1]', Mloc='double[:, ::1]', VE='double[:, ::1]', A='double[:, ::1]',
               G='double[:, ::1]')
cpdef Py_ssize_t _run(double[::1] par, double[::1] rt, double[::1] r0, double[::1] rs, Py_ssize_t cap, double[::1] tu0,
                      double[::1] thu, double[:, ::1] tuc, long long[::1] tdeg, signed char[::1] ugen, double[::1] ty0,
                      double[::1] tyh, double[:, ::1] tyc, double[:, ::1] tyd, signed char[::1] ygen, double[::1] out,
                      bint keep_y, double[::1] et, double[::1] ez, double[:, ::1] X, double[::1] buf,
                      double[:, :, ::1] mats) noexcept nogil
# (the batch's views are C-contiguous: _runs makes every work array, and its callers pass C-contiguous rows)
cpdef run_batch(double[:, ::1] pars, Py_ssize_t cap, Py_ssize_t nchunks, Py_ssize_t nsets=*)
cpdef run_sweep(double[::1] row, long long[::1] cols, double[:, ::1] vals, Py_ssize_t cap, Py_ssize_t nchunks,
                Py_ssize_t nsets=*)
@cython.locals(m=Py_ssize_t, s=Py_ssize_t)
cpdef _runs(double[:, ::1] pars, long long[::1] cols, double[:, ::1] vals, Py_ssize_t cap, Py_ssize_t nchunks,
            Py_ssize_t nsets)
@cython.locals(s=Py_ssize_t)
cpdef void _batch_sets(double[:, ::1] pars, long long[::1] cols, double[:, ::1] vals, Py_ssize_t cap,
                       Py_ssize_t nchunks, Py_ssize_t nsets, double[:, ::1] out, double[:, ::1] tu0,
                       double[:, ::1] thu, double[:, :, ::1] tuc, long long[:, ::1] tdeg, signed char[:, ::1] ugen,
                       double[:, ::1] ty0, double[:, ::1] tyh, double[:, :, ::1] tyc, double[:, :, ::1] tyd,
                       signed char[:, ::1] ygen, double[:, :, ::1] X, double[:, ::1] buf, double[:, :, :, ::1] mats,
                       double[:, ::1] ref, double[:, ::1] row, double[::1] none) noexcept nogil
@cython.locals(c=Py_ssize_t)
cpdef (Py_ssize_t, Py_ssize_t) _chunk(Py_ssize_t m, Py_ssize_t nchunks, Py_ssize_t nsets, Py_ssize_t s,
                                      Py_ssize_t k) noexcept nogil
@cython.locals(k=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, m=Py_ssize_t, nv=Py_ssize_t, lo=Py_ssize_t, hi=Py_ssize_t,
               par='double[::1]')
cpdef void _set_chunks(double[:, ::1] pars, long long[::1] cols, double[:, ::1] vals, Py_ssize_t cap,
                       Py_ssize_t nchunks, Py_ssize_t nsets, Py_ssize_t s, double[:, ::1] out, double[::1] tu0,
                       double[::1] thu, double[:, ::1] tuc, long long[::1] tdeg, signed char[::1] ugen,
                       double[::1] ty0, double[::1] tyh, double[:, ::1] tyc, double[:, ::1] tyd,
                       signed char[::1] ygen, double[:, ::1] X, double[::1] buf, double[:, :, ::1] mats,
                       double[::1] ref, double[::1] row, double[::1] none) noexcept nogil
