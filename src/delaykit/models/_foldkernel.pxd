# The C types of _foldkernel.py for Cython (the .py stays the one source; see spectrum/_rootkernel.pxd).
# fold_into is cpdef and nogil: the kernels of delaykit.simulate cimport it.
cimport cython

@cython.locals(i=Py_ssize_t, j=Py_ssize_t, v=Py_ssize_t, ym=double, vm=double)
cpdef double fold_into(const double[:] R, Py_ssize_t o, Py_ssize_t ldm, double dy, double dyd, double dvy, double dvv,
                       Py_ssize_t n, double[:, :] A, double[:] b, double[:] k) noexcept nogil
