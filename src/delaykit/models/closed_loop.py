"""A loop's closed-loop realisation, built in one place: the plant and the controller's realisation as one state
vector, with the signals that connect them through the delays and the limits.

The states are the plant's (``npl`` of them), then the controller's (:meth:`Controller.realisation
<delaykit.models.controllers.Controller.realisation>` or a compensator's); with ``w = u(t - Ti) + d`` the plant's
input, ``ym = y(t - To)`` and ``vm = y'(t - To)`` the measurement and its velocity, ``r`` the reference, ``v`` the
law's output and ``u = clip(v, umin, umax)`` the command::

    X'  = M X + bw w + br r + bym ym + bvm vm + baw (u - v) + bu u + bum u(t - Tm)
    y   = cy X + dy w,      y' = cyd X + dyd w
    v   = cv X + dvr r + dvy ym + dvv vm

(``M`` block diagonal: the plant's ``A`` and the controller's ``Ac``).  Every consumer builds from this:
the exact simulator's parameter rows (:mod:`delaykit.simulate._layout`), the time-varying-delay and the sampled
loops' matrices with the measurement read straight from the output (:meth:`LoopRealisation.folded`), and the
sampled spectrum.  :func:`delaykit.systems.from_loop` builds the same loop independently, block by block, by
:func:`~delaykit.systems.interconnect`; the tests check that the two agree.

Examples
--------
>>> from delaykit.models import Controller, Loop
>>> r = loop_realisation(Loop("1/((s+1)*(0.5*s+1))", Controller.pid(1.5, 0.8, 0.2, 0.05), delay=0.2))
>>> r.npl, r.M.shape, r.integ
(2, (4, 4), 2)
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from .controllers import Realisation
from .loop import Loop

__all__ = ["LoopRealisation", "Folded", "loop_realisation", "realisation_of"]


@dataclass(frozen=True)
class Folded:
    """The loop with the measurement read straight from the output (no output delay, or one moved to the input):
    ``X' = A X + b w + br r + bu u + bum u(t - Tm)``, ``y = cy X + dy w``, ``y' = cyd X + dyd w`` and the law's
    output ``v = k X + kw w + dvr r``.  Built by :meth:`LoopRealisation.folded`."""

    A: np.ndarray
    b: np.ndarray
    br: np.ndarray
    bu: np.ndarray
    bum: np.ndarray
    k: np.ndarray
    kw: float
    dvr: float


@dataclass(frozen=True)
class LoopRealisation:
    """A loop's closed-loop realisation (see the module docstring); built by :func:`loop_realisation`.

    ``integ`` is the index of the controller's integrator in the state vector (-1: none) and ``model_delay``
    the delay ``Tm`` of a compensator's model (0: none).
    """

    npl: int
    M: np.ndarray
    bw: np.ndarray
    br: np.ndarray
    bym: np.ndarray
    bvm: np.ndarray
    baw: np.ndarray
    cy: np.ndarray
    cyd: np.ndarray
    cv: np.ndarray
    bu: np.ndarray
    bum: np.ndarray
    dy: float
    dyd: float
    integ: int
    dvr: float
    dvy: float
    dvv: float
    model_delay: float

    @property
    def order(self) -> int:
        """Number of states (plant and controller)."""
        return int(self.M.shape[0])

    def folded(self) -> Folded:
        """The loop with ``ym = y`` and ``vm = y'`` substituted (the measurement without delay).

        Examples
        --------
        >>> from delaykit.models import Controller, Loop
        >>> f = loop_realisation(Loop("1/s", Controller.pi(2.0, 0.5))).folded()
        >>> f.A.tolist(), f.b.tolist(), f.k.tolist(), f.kw
        ([[0.0, 0.0], [-1.0, 0.0]], [1.0, 0.0], [-2.0, 0.5], 0.0)
        """
        n = self.order
        A, b, k = np.empty((n, n)), np.empty(n), np.empty(n)
        fk = _fold_kernel()
        R = np.concatenate([np.ravel(self.M)] + [getattr(self, name) for name in fk.PACKED], dtype=float)
        kw = fk.fold_into(R, 0, n, self.dy, self.dyd, self.dvy, self.dvv, n, A, b, k)
        return Folded(A=A, b=b, br=self.br, bu=self.bu, bum=self.bum, k=k, kw=float(kw), dvr=self.dvr)


def _fold_kernel() -> ModuleType:
    """The fold's kernel (:mod:`._foldkernel`) for Python callers: the extension where it was built, else the source
    run by the interpreter (a few hundred operations: numba's import would cost more than it saves);
    ``DELAYKIT_KERNELS`` chooses as for every kernel."""
    if not _fold:
        from .. import _native

        pkg = "delaykit.models"
        mode = os.environ.get("DELAYKIT_KERNELS") or ("cython" if _native.built(pkg, "_foldkernel") else "python")
        _fold.append(_native.load(pkg, "_foldkernel", mode))
    return _fold[0]


_fold: list[ModuleType] = []


def loop_realisation(loop: Loop) -> LoopRealisation:
    """The closed-loop realisation of a loop (see the module docstring): its plant's controllable canonical form,
    then its controller's realisation.

    Parameters
    ----------
    loop : Loop
        Any loop (continuous or sampled; a compensator reads the command ``u`` and ``u(t - Tm)``).

    Returns
    -------
    LoopRealisation

    Examples
    --------
    >>> from delaykit.models import Controller, Loop
    >>> r = loop_realisation(Loop("2/(s+1)", Controller.pv(1.0, 0.3)))
    >>> r.M.tolist(), r.cyd.tolist(), r.dyd, r.dvv
    ([[-1.0]], [-2.0], 2.0, -0.3)
    """
    A, B, C, D = loop.plant.state_space()
    return realisation_of(A, B, C, D, loop.controller.realisation())


def realisation_of(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: float, rz: Realisation) -> LoopRealisation:
    """The closed-loop realisation of the plant ``(A, B, C, D)`` (single input and output) under the controller
    realised by ``rz``: what :func:`loop_realisation` builds, for a plant given as matrices (a fit's trial plant).

    Examples
    --------
    >>> import numpy as np
    >>> from delaykit.models import Controller
    >>> r = realisation_of(np.array([[-1.0]]), np.array([1.0]), np.array([2.0]), 0.0, Controller.pi(1.0, 0.5).realisation())
    >>> r.M.tolist(), r.integ, r.dvy
    ([[-1.0, 0.0], [0.0, 0.0]], 1, -1.0)
    """
    A = np.atleast_2d(np.asarray(A, float))
    npl = A.shape[0]
    A = A.reshape(npl, npl)
    B = np.asarray(B, float).reshape(npl)
    C = np.asarray(C, float).reshape(npl)
    nc = rz.order
    n = npl + nc
    M = np.zeros((n, n))
    M[:npl, :npl] = A
    if nc:
        M[npl:, npl:] = rz.Ac
    zp, zc = np.zeros(npl), np.zeros(nc)
    return LoopRealisation(
        npl=npl, M=M, bw=np.r_[B, zc], br=np.r_[zp, rz.Bcr], bym=np.r_[zp, rz.Bcy], bvm=np.r_[zp, rz.Bcv],
        baw=np.r_[zp, rz.Baw], cy=np.r_[C, zc], cyd=np.r_[C @ A, zc], cv=np.r_[zp, rz.Cc],
        bu=np.r_[zp, rz.Bcu if rz.Bcu is not None else zc], bum=np.r_[zp, rz.Bcm if rz.Bcm is not None else zc],
        dy=float(D), dyd=float(C @ B), integ=npl + rz.integ if rz.integ >= 0 else -1,
        dvr=float(rz.dvr), dvy=float(rz.dvy), dvv=float(rz.dvv), model_delay=float(rz.model_delay),
    )
