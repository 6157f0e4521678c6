# The C types of _expmkernel.py for Cython (the .py stays the one source; see spectrum/_rootkernel.pxd).
# expm_into is cpdef and nogil: the kernels of delaykit.simulate cimport it.
cimport cython

@cython.locals(m=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, nrm=double, s=double)
cdef double _norm1(const double[:, :] X) noexcept nogil

@cython.locals(m=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, l=Py_ssize_t, k=Py_ssize_t, sq=Py_ssize_t, _=Py_ssize_t,
               nrm=double, f=double, b=double, rem=double, g=double, t=double)
cpdef double expm_into(const double[:, :] A, double[:, :] E, double[:, :] T, double[:, :] W) noexcept nogil

@cython.locals(q=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, E="double[:, ::1]", A="double[:, ::1]",
               work="double[:, :, ::1]")
cpdef expm(const double[:, :] M)
