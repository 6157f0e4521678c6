# The C types of _expmkernel.py for Cython (the .py stays the one source; see spectrum/_rootkernel.pxd).
# expm_into and mul_into are cpdef and nogil: the kernels of delaykit.simulate cimport them.
cimport cython

@cython.locals(n=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, k=Py_ssize_t, s=double)
cpdef void mul_into(const double[:, :] X, const double[:, :] Y, double[:, :] Z) noexcept nogil

@cython.locals(q=Py_ssize_t, norm=double, c=double, s=Py_ssize_t, sc=double, i=Py_ssize_t, j=Py_ssize_t,
               k=Py_ssize_t, big=double, _=Py_ssize_t)
cpdef void expm_into(double[:, :] X, double[:, :] E, double[:, :] T, double[:, :] W) noexcept nogil

@cython.locals(q=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, X="double[:, ::1]", E="double[:, ::1]",
               work="double[:, :, ::1]")
cpdef expm(const double[:, :] M)
