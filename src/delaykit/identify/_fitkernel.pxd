# The C types of _fitkernel.py for Cython: the .py stays the one source (run by Python or numba as it is); this
# file only declares what each name is when Cython compiles it to an extension module at build time (setup.py:
# no bounds or negative-index checks, as numba); the discrete simulator's loops are cimported from its .pxd.
cimport cython

cpdef Py_ssize_t order(long code) noexcept

@cython.locals(n=Py_ssize_t, mats="double[:, :, ::1]", vecs="double[:, ::1]")
cpdef tuple workspace(long code, Py_ssize_t size)

@cython.locals(n=Py_ssize_t, A="double[:, ::1]", B="double[::1]", C="double[::1]")
cpdef tuple realise(long code, const double[:] v)

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, a=double, b=double, k=double, wn=double, zeta=double,
               tz=double)
cpdef void realise_into(long code, const double[:] v, double[:, :] A, double[:] B, double[:] C) except *

@cython.locals(pos=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, s=Py_ssize_t, a0=Py_ssize_t, n0=Py_ssize_t,
               a1=Py_ssize_t, n1=Py_ssize_t, g00=double, g01=double, g11=double, b0=double, b1=double, w=double,
               ca=double, cc=double, rj=double, beta0=double, beta1=double, det=double)
cpdef void residual_blocks(const double[:] y, const double[:] dy, const double[:] uy, const double[:] udy,
                           const long long[:] starts, const long long[:] k0, const long long[:] p0,
                           const double[:] m0, const long long[:] k1, const long long[:] p1, const double[:] m1,
                           double w0, double w1, bint bias, bint offset, double[:] out)

cpdef int core(const double[:, :] phi, const double[:] ge, const double[:] gl, Py_ssize_t m, bint frac,
               const double[:] C, const double[:] ca, double cb, const double[:] drive, const long long[:] starts,
               bint closed, double kp, double kv, const double[:] lo, const double[:] hi, bint bias, bint offset,
               const long long[:] k0, const long long[:] p0, const double[:] m0, const long long[:] k1,
               const long long[:] p1, const double[:] m1, double w0, double w1, double[:] y, double[:] dy,
               double[:] uy, double[:] udy, double[:] u, double[:] x, double[:] xn, double[:] out) except? -1

@cython.locals(T=double, A="double[:, :]", B="double[:]", C="double[:]", n=Py_ssize_t, norm=double, i=Py_ssize_t,
               j=Py_ssize_t, m=Py_ssize_t, f=double, ca="double[:]", cb=double, phi="double[:, :]", ge="double[:]",
               gl="double[:]")
cpdef int evaluate(long code, const double[:] p, double h, double snap, const double[:] drive,
                   const long long[:] starts, bint closed, double kp, double kv, const double[:] lo,
                   const double[:] hi, bint bias, bint offset, const long long[:] k0, const long long[:] p0,
                   const double[:] m0, const long long[:] k1, const long long[:] p1, const double[:] m1, double w0,
                   double w1, double[:] y, double[:] dy, double[:] uy, double[:] udy, double[:] u,
                   double[:, :, :] mats, double[:, :] vecs, double[:] out) except? -1

@cython.locals(p="double[:]", i=Py_ssize_t, status=int)
cpdef int evaluate_fit(long code, const double[:] z, const unsigned char[:] pos, const double[:] rw, double h,
                       double snap, const double[:] drive, const long long[:] starts, bint closed, double kp,
                       double kv, const double[:] lo, const double[:] hi, bint bias, bint offset,
                       const long long[:] k0, const long long[:] p0, const double[:] m0, const long long[:] k1,
                       const long long[:] p1, const double[:] m1, double w0, double w1, double[:] y, double[:] dy,
                       double[:] uy, double[:] udy, double[:] u, double[:, :, :] mats, double[:, :] vecs,
                       double[:] out) except? -1

@cython.locals(zz="double[:]", i=Py_ssize_t, k=Py_ssize_t, step=double, dz=double, status=int, ok=bint)
cpdef int jacobian_fit(long code, const double[:] z, const unsigned char[:] pos, const double[:] lb,
                       const double[:] ub, const double[:] r0, const double[:] rw, double h, double snap,
                       const double[:] drive, const long long[:] starts, bint closed, double kp, double kv,
                       const double[:] lo, const double[:] hi, bint bias, bint offset, const long long[:] k0,
                       const long long[:] p0, const double[:] m0, const long long[:] k1, const long long[:] p1,
                       const double[:] m1, double w0, double w1, double[:] y, double[:] dy, double[:] uy,
                       double[:] udy, double[:] u, double[:, :, :] mats, double[:, :] vecs, double[:] col,
                       double[:, :] J) except? -1

@cython.locals(s=double, i=Py_ssize_t)
cpdef double dot(const double[:] a, const double[:] b) noexcept

@cython.locals(m=Py_ssize_t, n=Py_ssize_t, A="double[:, ::1]", g="double[::1]", k=Py_ssize_t, i=Py_ssize_t,
               j=Py_ssize_t, rk=double, a=double)
cpdef tuple normal_equations(const double[:, :] J, const double[:] r)
