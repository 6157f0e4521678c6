# The C types of _noisekernel.py for Cython: the .py stays the one source (run by Python or numba as it is); this
# file only declares what each name is when Cython compiles it to an extension module at build time (setup.py:
# no bounds or negative-index checks, as numba).
cimport cython

@cython.locals(n=Py_ssize_t, d=Py_ssize_t, q=Py_ssize_t, p=Py_ssize_t, X="double[:, :, ::1]", m=Py_ssize_t,
               a=Py_ssize_t, c=Py_ssize_t, i=Py_ssize_t, b=Py_ssize_t, s=double)
cpdef var_backward(const double[:, :, :] J, const double[:, :, :] phi)

@cython.locals(n=Py_ssize_t, K=Py_ssize_t, z="double[::1]", c=Py_ssize_t, k=Py_ssize_t, i=Py_ssize_t, xn=double,
               yn=double)
cpdef void linear_filter(const double[:] b, const double[:] a, const double[:, :] x, double[:, :] y)
