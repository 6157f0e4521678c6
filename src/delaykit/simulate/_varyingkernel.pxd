# The C types of _varyingkernel.py for Cython (the .py stays the one source; see spectrum/_rootkernel.pxd).
cimport cython

@cython.locals(q=Py_ssize_t, n=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, e=Py_ssize_t, k=Py_ssize_t, z="double[::1]",
               zn="double[::1]", E="double[:, ::1]", X="double[:, ::1]", T="double[:, ::1]", W="double[:, ::1]",
               t=double, last=double, t_switch=double, w_left=double, tau=double, acc=double, v=double, y=double,
               dy=double)
cpdef void events(const double[:, :] M, const double[:, :] rows, double lo, double hi, double r,
                  const double[:] ev_t, const long long[:] ev_kind, const long long[:] ev_idx, double[:] u_cmd,
                  double[:, :] rec)
