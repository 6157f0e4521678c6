# The C types of _kernel.py for Cython (the .py is the one source; see _poly.pxd).  The piece loop and its helpers
# run without the GIL; run_batch's loop over work sets runs in parallel (OpenMP, where setup.py found it).
cimport cython

cdef Py_ssize_t DEG, MAXN, NC, NOUT, OFF_BAW, OFF_BR, OFF_BU, OFF_BUM, OFF_BVM, OFF_BW, OFF_BYM, OFF_CV, OFF_CY
cdef Py_ssize_t OFF_CYD, OFF_M, _GRID, _LIN, _HIGH, _LOW
cdef double SELF, _GROW, STATUS_CAPACITY, STATUS_OK, STATUS_STALLED, _INF, _NAN
cdef double[:, ::1] _BIN
cdef Py_ssize_t _N, _TI, _TO, _UMIN, _UMAX, _PERIOD, _OFFSET, _T_END, _BAND, _NORM, _DIST, _T_DIST, _DY, _DYD
cdef Py_ssize_t _DVR, _DVY, _DVV, _INTEG, _AW, _HMAX, _SCALE, _STEP, _SLOPE, _TM
cdef Py_ssize_t _STALL, _NONE, _PICARD, _WMAX, _TPEAK, _T10, _T90, _TLAST, _WEND, _NMS, _NBUF
cdef double _TAIL, _JUMP

@cython.locals(j=Py_ssize_t)
cpdef Py_ssize_t _classify(double[:] V, Py_ssize_t n, double umin, double umax, double tol) noexcept nogil
cpdef Py_ssize_t _delayed(double[:] t0, double[:] th, double[:, :] tc, long long[:] tdeg, Py_ssize_t q, double s,
                          double H, double[:] dst, double[:] work) noexcept nogil
cpdef Py_ssize_t _ref_poly(double[:] rt, double[:] r0, double[:] rs, Py_ssize_t k, double a, double H,
                           double[:] R) noexcept nogil
@cython.locals(i=Py_ssize_t, j=Py_ssize_t)
cpdef double _tail(double[:, :] X, Py_ssize_t N, double[:] V, Py_ssize_t nt) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef void _step_metrics(double[:] Y, Py_ssize_t nY, double norm, double a, double H, double band, double[:] ms,
                         double[:] Wn, double[:] dW, double[:] xs, double[:] fs, long long[:] sd) noexcept nogil
@cython.locals(i=Py_ssize_t)
cpdef void _metrics_row(double[:] out, bint metrics, double wmax, double wend, double tpeak, double t10, double t90,
                        double tlast, double norm, double band) noexcept nogil
@cython.locals(m=Py_ssize_t, j=Py_ssize_t, i=Py_ssize_t, idx=Py_ssize_t, k=Py_ssize_t)
cpdef void _metrics_update(double[:] Wn, Py_ssize_t nW, double a, double H, double band, double[:] ms, double[:] dW,
                           double[:] xs, double[:] fs, double[:] sr, long long[:] sd, bint certified) noexcept nogil
cpdef double _first_switch(double[:] V, Py_ssize_t nv, double[:] E, Py_ssize_t ne, Py_ssize_t regime, bint frozen,
                           double umin, double umax, Py_ssize_t aw, double[:] fs) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef bint _continues(double[:] t0, double[:] th, double[:, :] tc, long long[:] deg, bint full, Py_ssize_t n,
                      Py_ssize_t q, double s, double tol) noexcept nogil
cpdef Py_ssize_t _on_limit(double v0, double[:] E, Py_ssize_t ne, double umin, double umax,
                           double tol) noexcept nogil
@cython.locals(j=Py_ssize_t)
cpdef double _lead_sign(double[:] c, Py_ssize_t n, double tol) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef Py_ssize_t _slide_rates(double[:, :] X, Py_ssize_t integ, double[:] Fz, Py_ssize_t nt, double[:] S,
                              double[:] D) noexcept nogil
cpdef (Py_ssize_t, Py_ssize_t, double, Py_ssize_t) _image(double[:] t0, signed char[:] gen, Py_ssize_t n,
                                                          Py_ssize_t q, Py_ssize_t qg, double s, double a,
                                                          double delay, double eps) noexcept nogil
cpdef (Py_ssize_t, Py_ssize_t, double, Py_ssize_t, bint) _pending(double[:] t0, signed char[:] gen, Py_ssize_t n,
                                                                  Py_ssize_t q, Py_ssize_t qg, double s, double a,
                                                                  double delay, double eps,
                                                                  bint can_self) noexcept nogil
cpdef double _read_end(double[:] t0, double[:] th, double[:, :] tc, long long[:] tdeg, bint full, Py_ssize_t n,
                       Py_ssize_t q, double delay, double end, double ctol) noexcept nogil
@cython.locals(i=Py_ssize_t, k=Py_ssize_t, m=Py_ssize_t)
cpdef Py_ssize_t _rel_degree(double[:, :] Mloc, double[:, :] VE, Py_ssize_t N, Py_ssize_t row_out,
                             Py_ssize_t row_in, Py_ssize_t k0, double[:] v, double[:] w) noexcept nogil
@cython.locals(j=Py_ssize_t, d=double, size=double, b=double, r=double, c=double)
cpdef (double, double) _jump(double[:] cl, Py_ssize_t nl, double hl, double[:] cr, Py_ssize_t nr, double hr,
                             double L, double[:] tmp, double[:] work) noexcept nogil
@cython.locals(k=Py_ssize_t, j=Py_ssize_t)
cpdef (double, Py_ssize_t) _picard(double[:] src, Py_ssize_t n, double delta, double[:] dst) noexcept nogil
@cython.locals(k=Py_ssize_t)
cpdef Py_ssize_t _held(double[:] c, Py_ssize_t n, double x, double[:] dst) noexcept nogil
@cython.locals(X='double[:, :]', buf='double[:]', mats='double[:, :, :]')
cpdef Py_ssize_t run_one(double[:] par, double[:] rt, double[:] r0, double[:] rs, Py_ssize_t cap, double[:] tu0,
                         double[:] thu, double[:, :] tuc, long long[:] tdeg, signed char[:] ugen, double[:] ty0,
                         double[:] tyh, double[:, :] tyc, double[:, :] tyd, signed char[:] ygen, double[:] out,
                         bint keep_y, double[:] et, double[:] ez)
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
               regime_matters=bint, known=bint, slide_on=bint, neutral=bint, zero_a=bint, u_img=bint, y_img=bint,
               self_ok=bint, self_u=bint, self_y=bint, self_m=bint, self_any=bint, dist_on=bint, frozen=bint,
               sliding=bint, tried=bint, failed=bint, newf=bint, changed=bint, cut=bint, u_src=bint, y_src=bint,
               R='double[:]', Wd='double[:]', Um='double[:]', Ym='double[:]', Vm='double[:]', Y='double[:]',
               Yd='double[:]', V='double[:]', E='double[:]', Wn='double[:]', dW='double[:]', work='double[:]',
               Fz='double[:]', S='double[:]', D='double[:]', xs='double[:]', fs='double[:]', x0='double[:]',
               d5='double[:]', ms='double[:]', src='double[:]', rv='double[:]', rw='double[:]', Mloc='double[:, :]',
               VE='double[:, :]', A='double[:, :]', G='double[:, :]')
cpdef Py_ssize_t _run(double[:] par, double[:] rt, double[:] r0, double[:] rs, Py_ssize_t cap, double[:] tu0,
                      double[:] thu, double[:, :] tuc, long long[:] tdeg, signed char[:] ugen, double[:] ty0,
                      double[:] tyh, double[:, :] tyc, double[:, :] tyd, signed char[:] ygen, double[:] out,
                      bint keep_y, double[:] et, double[:] ez, double[:, :] X, double[:] buf,
                      double[:, :, :] mats) noexcept nogil
cpdef run_batch(double[:, :] pars, Py_ssize_t cap, Py_ssize_t nchunks, Py_ssize_t nsets=*)
@cython.locals(s=Py_ssize_t)
cpdef void _batch_sets(double[:, :] pars, Py_ssize_t cap, Py_ssize_t nchunks, Py_ssize_t nsets, double[:, :] out,
                       double[:, :] tu0, double[:, :] thu, double[:, :, :] tuc, long long[:, :] tdeg,
                       signed char[:, :] ugen, double[:, :] ty0, double[:, :] tyh, double[:, :, :] tyc,
                       double[:, :, :] tyd, signed char[:, :] ygen, double[:, :, :] X, double[:, :] buf,
                       double[:, :, :, :] mats, double[:, :] ref, double[:] none) noexcept nogil
@cython.locals(k=Py_ssize_t, i=Py_ssize_t, m=Py_ssize_t, lo=Py_ssize_t, hi=Py_ssize_t, c=Py_ssize_t)
cpdef void _set_chunks(double[:, :] pars, Py_ssize_t cap, Py_ssize_t nchunks, Py_ssize_t nsets, Py_ssize_t s,
                       double[:, :] out, double[:] tu0, double[:] thu, double[:, :] tuc, long long[:] tdeg,
                       signed char[:] ugen, double[:] ty0, double[:] tyh, double[:, :] tyc, double[:, :] tyd,
                       signed char[:] ygen, double[:, :] X, double[:] buf, double[:, :, :] mats, double[:] ref,
                       double[:] none) noexcept nogil
