# The C types of _trackkernel.py for Cython (the .py stays the one source; see _rootkernel.pxd).
cimport cython

@cython.locals(C="double complex[:, ::1]", A="double[:, ::1]", tau="double[::1]", found="double complex[::1]",
               sout="double complex[::1]", conv="unsigned char[::1]", clean="unsigned char[::1]",
               p0="double complex[::1]", oth="double[::1]", box="double[::1]", n_init="long long[::1]",
               cs="double complex[::1]", csr="double[::1]", buf="double complex[::1]", buf2="double complex[::1]",
               state="long long[::1]", size=Py_ssize_t, k=Py_ssize_t, sa="double complex[::1]",
               sb="double complex[::1]", wa="double complex[::1]", wb="double complex[::1]", ra="double[::1]",
               rb="double[::1]")
cpdef track(const double complex[:, :] Wc, const double[:, :] Wt, Py_ssize_t nt, Py_ssize_t n1, Py_ssize_t k0,
            double complex[:] starts, Py_ssize_t nstart, bint sym, double[:] absc, double max_phase, double reliable,
            Py_ssize_t cap)

@cython.locals(nstart=Py_ssize_t, k=Py_ssize_t, i=Py_ssize_t, j=Py_ssize_t, nf=Py_ssize_t, c=Py_ssize_t,
               m=Py_ssize_t, e=Py_ssize_t, ni=Py_ssize_t, total_init=Py_ssize_t, taumax=double, z="double complex",
               zz="double complex", top="double complex", new=bint, x=double, R=double, y0=double, status=int,
               total=double, nearest=double, used=Py_ssize_t, where="double complex", want=Py_ssize_t)
cpdef Py_ssize_t track_points(const double complex[:, :] Wc, const double[:, :] Wt, Py_ssize_t nt, Py_ssize_t n1,
                              Py_ssize_t k0, double complex[:] starts, double[:] absc, bint sym, double max_phase,
                              double reliable, Py_ssize_t cap, double complex[:, :] C, double[:, :] A,
                              double[:] tau, double complex[:] found, double complex[:] sout, unsigned char[:] conv,
                              unsigned char[:] clean, double complex[:] p0, double[:] oth, const double[:] box,
                              long long[:] n_init, double complex[:] cs, double[:] csr, double complex[:] buf,
                              double complex[:] buf2, double complex[:] sa, double complex[:] sb,
                              double complex[:] wa, double complex[:] wb, double[:] ra, double[:] rb,
                              long long[:] state) noexcept nogil
