"""Interconnections of delay systems: every one is a block-diagonal stack closed by a static interconnection.

Series, parallel, feedback and named interconnection are all written once, as :func:`close`: the blocks are
stacked (:func:`append`, inputs ``v`` and outputs ``e``) and closed by ``v = F e + G u``, ``y = H e + J u`` with
constant matrices.  Substituting into the partitioned equations of :class:`~delaykit.systems.lti.DelayLTI` gives
again a system of that form, whose delay channels are the blocks' own; the one condition is that the algebraic
loop through the direct feedthroughs is well posed, ``I - D11 F`` invertible.  Delays are never approximated.

Names follow python-control: ``G * H`` is the series connection with ``H`` first, ``feedback(sys1, sys2, sign)``
puts ``sys2`` in the return path with ``u1 = r + sign * y2``, and :func:`interconnect` connects signals by name.

Examples
--------
>>> from delaykit import tf, feedback
>>> T = feedback(tf("2*exp(-0.1*s)/(s+1)"), 1)
>>> T.ndelays, round(float(T.dcgain()[0, 0]), 6)
(1, 0.666667)
"""

from __future__ import annotations

import math
import numbers
import reprlib
from typing import Any, Sequence

import numpy as np

from ..errors import InvalidTypeError, InvalidValueError, check_real, plain
from ..models.budget import MAX_MATRIX_ELEMENTS, check_count
from .lti import DelayLTI

__all__ = ["as_system", "close", "close_parts", "blockdiag", "append", "product", "sum_of", "series", "parallel",
           "negate", "feedback",
           "select", "interconnect", "summing_junction", "gain"]

_COND_LIMIT = 1e12  # I - D11 F with a larger condition number is taken as singular


def gain(K: Any, *, inputs: Any = None, outputs: Any = None, name: str = "") -> DelayLTI:
    """A static gain matrix ``y = K u`` as a system.

    Examples
    --------
    >>> gain([[1.0, -1.0]])
    DelayLTI(2 inputs ['u[0]', 'u[1]'] -> 1 output ['y[0]'], 0 states, no delays)
    """
    if isinstance(K, (bool, np.bool_)):
        raise InvalidTypeError(f"a gain must be a real number or matrix, got {K!r} (a bool): write 1 or 0")
    try:
        k = np.array(K, dtype=float)
    except OverflowError:  # an integer beyond the floats (10**400)
        if isinstance(K, int):
            check_real("a gain", K)  # names it by its number of digits
        raise InvalidValueError(f"a gain must be finite: {reprlib.repr(K)} holds an integer beyond the floats"
                                ) from None
    except (TypeError, ValueError) as exc:
        raise InvalidTypeError(f"a gain must be a real number or matrix, got {reprlib.repr(K)}") from exc
    if k.ndim > 2:
        raise InvalidValueError(f"a gain must be a number or a matrix, got shape {k.shape}")
    if not np.isfinite(k).all():
        bad = float(k[~np.isfinite(k)][0])
        raise InvalidValueError(f"a gain must be finite, got {bad!r}" + ("" if k.ndim == 0 else f" in {k.tolist()}"))
    k = k.reshape(1, 1) if k.ndim == 0 else k.reshape(1, -1) if k.ndim == 1 else k
    if k.size == 0:
        return DelayLTI(D11=k, inputs=inputs, outputs=outputs, name=name)
    ny, nu = k.shape
    z = np.zeros
    return DelayLTI._from_parts((z((0, 0)), z((0, nu)), z((0, 0)), z((ny, 0)), z((0, 0)), k, z((ny, 0)), z((0, nu)),
                                 z((0, 0))), (), None, inputs, outputs, name, finite=True)


def as_system(x: Any, what: str = "operand") -> DelayLTI:
    """``x`` as a :class:`DelayLTI`: a system as it is, a number or matrix as a static gain, anything else that
    :func:`delaykit.tf` reads (a :class:`~delaykit.models.TransferFunction`, a python-control system).

    Examples
    --------
    >>> as_system(2.0).dcgain().tolist()
    [[2.0]]
    """
    if isinstance(x, DelayLTI):
        return x
    if isinstance(x, (numbers.Real, np.ndarray)) and not isinstance(x, (bool, np.bool_)):
        try:
            return gain(x)
        except (InvalidValueError, InvalidTypeError) as exc:
            raise type(exc)(f"{what}: {exc}") from None
    if isinstance(x, str):
        raise InvalidTypeError(f"{what}: text is read by tf('...'), not combined with a system directly; got {x!r}")
    if isinstance(x, (bool, np.bool_)):  # python-control would take True as the gain 1; delaykit asks
        raise InvalidTypeError(f"{what}: {x!r} is a bool, not a gain or a system; write the number 1 or 0, or a "
                               "system")
    from .build import tf

    return tf(x)


def _partitions(sys: DelayLTI) -> tuple[np.ndarray, ...]:
    return sys.A, sys.B1, sys.B2, sys.C1, sys.C2, sys.D11, sys.D12, sys.D21, sys.D22


def close(sys: DelayLTI, F: np.ndarray, G: np.ndarray, H: np.ndarray, J: np.ndarray, *, inputs: Any = None,
          outputs: Any = None, name: str = "", what: str = "the interconnection") -> DelayLTI:
    """``sys`` (inputs ``v``, outputs ``e``) closed by ``v = F e + G u``, ``y = H e + J u``.

    Raises
    ------
    InvalidValueError
        When the algebraic loop is not well posed (``I - D11 F`` singular).

    Examples
    --------
    Unity negative feedback around an integrator, ``v = u - e``:

    >>> T = close(gain(1.0) * DelayLTI(A=[[0.0]], B1=[[1.0]], C1=[[1.0]]), np.array([[-1.0]]), np.eye(1),
    ...           np.eye(1), np.zeros((1, 1)))
    >>> T.A.tolist()
    [[-1.0]]
    """
    return _closed((_partitions(sys), sys.delays, sys.limits), F, G, H, J, inputs, outputs, name, what)


_Stack = tuple[tuple[np.ndarray, ...], tuple[float, ...], tuple[tuple[float, float], ...]]


def _closed(stack: _Stack, F: np.ndarray, G: np.ndarray, H: np.ndarray, J: np.ndarray, inputs: Any, outputs: Any,
            name: Any, what: str, names_checked: bool = False) -> DelayLTI:
    """:func:`close` of a system given as ``(parts, delays, limits)`` (:func:`_stack`); ``names_checked`` when the
    names are systems' own tuples (see ``DelayLTI._from_parts``)."""
    parts, delays, limits = stack
    return DelayLTI._from_parts(close_parts(parts, F, G, H, J, what), delays, limits, inputs, outputs, name,
                                names_checked=names_checked, finite=True)  # close_parts checked finiteness


def close_parts(parts: Sequence[np.ndarray], F: Any, G: Any, H: Any, J: Any, what: str = "the interconnection"
                ) -> tuple[np.ndarray, ...]:
    """The partitioned matrices ``(A, B1, B2, C1, C2, D11, D12, D21, D22)`` closed as :func:`close` does.

    Pure matrix algebra: it holds for a discrete-time system as well (``x[k+1]`` for ``x'``).

    Raises
    ------
    InvalidValueError
        When the algebraic loop is not well posed, or a result overflows (an entry beyond the largest float).

    Examples
    --------
    >>> from delaykit import tf
    >>> g = tf("1/s")                                    # x' = u, y = x; closed by u = -y + r: x' = -x + r
    >>> parts = (g.A, g.B1, g.B2, g.C1, g.C2, g.D11, g.D12, g.D21, g.D22)
    >>> close_parts(parts, -np.eye(1), np.eye(1), np.eye(1), np.zeros((1, 1)))[0].tolist()
    [[-1.0]]
    """
    A, B1, B2, C1, C2, D11, D12, D21, D22 = parts
    ne, nv = D11.shape
    F, G, H, J = (np.asarray(M, dtype=float) for M in (F, G, H, J))
    with np.errstate(all="ignore"):  # an overflow is reported below, naming the matrix
        LF = D11 @ F  # the direct feedthrough around the loops
        M = np.eye(ne) - LF
        # M = I without LF, whose condition number is 1; a large one is a singular loop, unless the feedthroughs
        # close no loop at all (a chain: M is unit triangular, invertible whatever the gains' sizes)
        if ne and LF.any() and not _cond(M) <= _COND_LIMIT:
            if not np.isfinite(LF).all():
                _overflow(what, "D11 F", "the direct feedthrough around the loops", parts)
            if not _chain(LF):
                raise InvalidValueError(f"{what} is not well posed: its algebraic loop (direct feedthroughs around "
                                        "a loop, I - D F singular) has no unique solution; add dynamics or change a "
                                        "gain")
        X = (np.linalg.solve(M, np.concatenate([C1, D11 @ G, D12], axis=1)) if ne
             else np.zeros((0, C1.shape[1] + G.shape[1] + D12.shape[1])))
        n, nu = A.shape[0], G.shape[1]
        Ce, Deu, Dew = X[:, :n], X[:, n:n + nu], X[:, n + nu:]
        BF, DF = B1 @ F, D21 @ F
        out = (A + BF @ Ce, B1 @ G + BF @ Deu, B2 + BF @ Dew, H @ Ce, C2 + DF @ Ce, H @ Deu + J, H @ Dew,
               D21 @ G + DF @ Deu, D22 + DF @ Dew)
    if not np.isfinite(np.concatenate([m.ravel() for m in out])).all():
        k = next(k for k, m in enumerate(out) if not np.isfinite(m).all())
        _overflow(what, _PART_NAMES[k], _PART_MEANING[k], parts)
    return out


_PART_NAMES = ("A", "B1", "B2", "C1", "C2", "D11", "D12", "D21", "D22")
_PART_MEANING = ("the state matrix", "from the inputs to the states", "from the delay channels to the states",
                 "from the states to the outputs", "from the states to the delay channels",
                 "the direct feedthrough from the inputs to the outputs", "from the delay channels to the outputs",
                 "from the inputs to the delay channels", "between the delay channels")


def _overflow(what: str, name: str, meaning: str, parts: Sequence[np.ndarray]) -> None:
    """Raise the error of a result beyond the floats: which matrix, and the largest entry it came from."""
    big = max((float(np.abs(m).max()) for m in parts if m.size), default=0.0)
    raise InvalidValueError(f"{what} overflows: the result's {name} ({meaning}) would have an entry beyond the "
                            f"largest float (1.8e+308); the blocks' entries, up to {big:g}, multiply to more than "
                            "that; rescale the signals (their units) to smaller gains")


def _cond(M: np.ndarray) -> float:
    """The condition number of ``M``; inf when its SVD fails (an entry that overflowed)."""
    try:
        return float(np.linalg.cond(M))
    except np.linalg.LinAlgError:
        return math.inf


def _chain(LF: np.ndarray) -> bool:
    """True when the nonzero entries of ``LF`` close no loop (its graph has no cycle, so ``LF`` is nilpotent and
    ``I - LF`` has determinant 1): sources are removed until none is left."""
    edges = LF != 0
    alive = np.ones(edges.shape[0], bool)
    while alive.any():
        idx = np.flatnonzero(alive)
        source = ~edges[np.ix_(idx, idx)].any(axis=1)  # fed by no remaining signal (row i: what feeds signal i)
        if not source.any():
            return False
        alive[idx[source]] = False
    return True


def blockdiag(*ms: np.ndarray) -> np.ndarray:
    """The matrices on the diagonal of one (any shapes, empty ones included).

    Examples
    --------
    >>> blockdiag(np.ones((1, 2)), np.zeros((0, 0)), 2 * np.eye(1)).tolist()
    [[1.0, 1.0, 0.0], [0.0, 0.0, 2.0]]
    """
    shapes = [m.shape for m in ms]
    out = np.zeros((sum(s[0] for s in shapes), sum(s[1] for s in shapes)))
    r = c = 0
    for m, (p, q) in zip(ms, shapes):
        if p and q:
            out[r:r + p, c:c + q] = m
        r, c = r + p, c + q
    return out


def _distinct_or_none(names: list[str]) -> tuple[str, ...] | None:
    return tuple(names) if len(set(names)) == len(names) else None


def append(*systems: Any) -> DelayLTI:
    """The systems side by side (block-diagonal): inputs and outputs, states and delay channels stacked.

    The signal names are kept when they stay distinct (python-control's default names otherwise).

    Examples
    --------
    >>> from delaykit import tf
    >>> append(tf("exp(-s)/(s+1)"), tf("2*exp(-3*s)/(s+2)"))
    DelayLTI(2 inputs ['u[0]', 'u[1]'] -> 2 outputs ['y[0]', 'y[1]'], 2 states, delays [1, 3] s)
    """
    if not systems:
        raise InvalidValueError("append needs at least one system")
    ss = [as_system(s, f"system {k}") for k, s in enumerate(systems)]
    ins = _distinct_or_none([x for s in ss for x in s.inputs])
    outs = _distinct_or_none([x for s in ss for x in s.outputs])
    return DelayLTI._from_parts(*_stack(ss), ins, outs, names_checked=True, finite=True)


def _stack(ss: Sequence[DelayLTI]) -> _Stack:
    """The parts, delays and limits of :func:`append`'s result, without making it a system."""
    n, m = sum(s.nstates for s in ss), sum(s.ndelays for s in ss)
    check_count(f"a system of {n} states and {m} delay channels", float(n + m) ** 2, MAX_MATRIX_ELEMENTS,
                "matrix elements", "build a smaller system")  # (its parts are (n + m) x (n + m) at most, dense)
    parts = [_partitions(s) for s in ss]
    return (tuple(blockdiag(*(p[k] for p in parts)) for k in range(9)), tuple(t for s in ss for t in s.delays),
            tuple(p for s in ss for p in s.limits))


def _check_sizes(what: str, need: int, got: int, left: DelayLTI, right: DelayLTI) -> None:
    if need != got:
        raise InvalidValueError(f"{what}: sizes do not match ({need} against {got}): {left!r} and {right!r}")


def series(*systems: Any) -> DelayLTI:
    """Systems in series, the first one first, as python-control's ``series``: ``series(a, b, c) = c * b * a``.

    Each system's outputs feed the next one's inputs (as many of each); a number or a matrix is a gain.

    Examples
    --------
    >>> from delaykit import tf
    >>> series(tf("1/(s+1)"), tf("exp(-2*s)")).delays
    (2.0,)
    >>> T = series(tf("2"), tf("1/(s+1)"), tf("exp(-s)"))
    >>> round(float(T.dcgain()[0, 0]), 12)
    2.0
    """
    if not systems:
        raise InvalidValueError("series needs at least one system")
    out = as_system(systems[0], "the first system")
    for k, nxt in enumerate(systems[1:], 2):
        out = product(as_system(nxt, f"system {k}"), out)
    return out


def parallel(*systems: Any) -> DelayLTI:
    """Systems in parallel, as python-control's ``parallel``: ``parallel(a, b, c) = a + b + c`` (the same inputs
    into each, the outputs added; the first system names the signals).

    Examples
    --------
    >>> from delaykit import tf
    >>> parallel(tf("1/(s+1)"), 1, tf("exp(-s)")).dcgain().tolist()
    [[3.0]]
    """
    if not systems:
        raise InvalidValueError("parallel needs at least one system")
    out = as_system(systems[0], "the first system")
    for k, nxt in enumerate(systems[1:], 2):
        out = sum_of(out, as_system(nxt, f"system {k}"))
    return out


def product(G: Any, H: Any) -> DelayLTI:
    """``G * H``: ``H`` first, its outputs into ``G``'s inputs (:func:`series` with the order of the product).

    Examples
    --------
    >>> from delaykit import tf
    >>> product(tf("1/(s+1)"), tf("exp(-2*s)")).delays
    (2.0,)
    """
    G, H = as_system(G, "left factor"), as_system(H, "right factor")
    if G.ninputs == 1 and G.noutputs == 1 and G.nstates == 0 and G.ndelays == 0 and H.noutputs != 1:
        G = gain(G.D11[0, 0] * np.eye(H.noutputs))  # a scalar gain times a MIMO system
    if H.ninputs == 1 and H.noutputs == 1 and H.nstates == 0 and H.ndelays == 0 and G.ninputs != 1:
        H = gain(H.D11[0, 0] * np.eye(G.ninputs))
    _check_sizes("G * H needs as many outputs of H as inputs of G", H.noutputs, G.ninputs, G, H)
    P = _stack((G, H))
    ny, nu, k = G.noutputs, H.ninputs, G.ninputs
    F = np.zeros((k + nu, ny + k))
    F[:k, ny:] = np.eye(k)
    Gm = np.vstack([np.zeros((k, nu)), np.eye(nu)])
    Hm = np.hstack([np.eye(ny), np.zeros((ny, k))])
    return _closed(P, F, Gm, Hm, np.zeros((ny, nu)), H.inputs, G.outputs, "", "G * H", names_checked=True)


def sum_of(G: Any, H: Any) -> DelayLTI:
    """``G + H``: the same inputs into both, the outputs added.

    Examples
    --------
    >>> from delaykit import tf
    >>> (tf("1/(s+1)") + 1).dcgain().tolist()
    [[2.0]]
    """
    G, H = as_system(G, "left term"), as_system(H, "right term")
    if G.ninputs == G.noutputs == 1 and G.nstates == G.ndelays == 0 and H.ninputs == H.noutputs != 1:
        G = gain(G.D11[0, 0] * np.eye(H.noutputs))
    if H.ninputs == H.noutputs == 1 and H.nstates == H.ndelays == 0 and G.ninputs == G.noutputs != 1:
        H = gain(H.D11[0, 0] * np.eye(G.noutputs))
    _check_sizes("G + H needs the same number of inputs", G.ninputs, H.ninputs, G, H)
    _check_sizes("G + H needs the same number of outputs", G.noutputs, H.noutputs, G, H)
    P = _stack((G, H))
    ny, nu = G.noutputs, G.ninputs
    F = np.zeros((2 * nu, 2 * ny))
    Gm = np.vstack([np.eye(nu), np.eye(nu)])
    Hm = np.hstack([np.eye(ny), np.eye(ny)])
    return _closed(P, F, Gm, Hm, np.zeros((ny, nu)), G.inputs, G.outputs, "", "G + H", names_checked=True)


def negate(G: DelayLTI) -> DelayLTI:
    """``-G``: the outputs negated.

    Examples
    --------
    >>> from delaykit import tf
    >>> negate(tf("exp(-s)/(s+1)")).dcgain().tolist()
    [[-1.0]]
    """
    return DelayLTI._from_parts((G.A, G.B1, G.B2, -G.C1, G.C2, -G.D11, -G.D12, G.D21, G.D22), G.delays, G.limits,
                                G.inputs, G.outputs, G.name, names_checked=True)


def feedback(sys1: Any, sys2: Any = 1, sign: int = -1) -> DelayLTI:
    """The closed loop of ``sys1`` (forward path) and ``sys2`` (return path): ``y = sys1 (u + sign sys2 y)``.

    Parameters
    ----------
    sys1 : DelayLTI or anything :func:`as_system` takes
        The forward path.
    sys2 : DelayLTI, number or matrix
        The return path (default 1: unity feedback; a number is taken times the identity for MIMO).
    sign : {-1, 1}
        -1 for negative feedback (python-control's default).

    Raises
    ------
    InvalidValueError
        For sizes that do not match, or an algebraic loop that is not well posed (``feedback(1, 1, sign=1)``).

    Examples
    --------
    The FOPDT ``G = 2 e^{-s} / (s + 1)`` under unity feedback at ``w = 1``:

    >>> import numpy as np
    >>> from delaykit import tf
    >>> T = feedback(tf("2*exp(-s)/(s+1)"))
    >>> g = 2 * np.exp(-1j) / (1j + 1)
    >>> bool(abs(T.frequency_response([1.0]).response[0, 0, 0] - g / (1 + g)) < 1e-14)
    True
    """
    if isinstance(sign, bool) or not isinstance(sign, numbers.Real) or sign not in (1, -1):
        raise InvalidValueError(f"sign must be -1 (negative feedback) or +1, got {plain(sign)!r:.60}")
    sys1 = as_system(sys1, "forward path")
    # feedback(L, 1): the return path's gain made once (times the identity for MIMO); other numbers as before
    number = (type(sys2) is float and math.isfinite(sys2)) or (type(sys2) is int and abs(sys2) <= 2 ** 53)
    sys2 = sys2 if number else as_system(sys2, "return path")
    if sys1.noutputs != 1 and (number or (sys2.ninputs == sys2.noutputs == 1 and sys2.nstates == sys2.ndelays == 0)):
        if sys1.ninputs != sys1.noutputs:
            raise InvalidValueError(f"a scalar return path needs a square forward path, got {sys1!r}")
        sys2 = gain((float(sys2) if number else sys2.D11[0, 0]) * np.eye(sys1.noutputs))
    elif number:
        sys2 = gain(sys2)
    _check_sizes("feedback needs as many inputs of the return path as outputs of the forward path",
                 sys1.noutputs, sys2.ninputs, sys1, sys2)
    _check_sizes("feedback needs as many outputs of the return path as inputs of the forward path",
                 sys1.ninputs, sys2.noutputs, sys1, sys2)
    P = _stack((sys1, sys2))
    ny, nu = sys1.noutputs, sys1.ninputs
    F = np.zeros((nu + ny, ny + nu))
    F[:nu, ny:] = sign * np.eye(nu)
    F[nu:, :ny] = np.eye(ny)
    Gm = np.vstack([np.eye(nu), np.zeros((ny, nu))])
    Hm = np.hstack([np.eye(ny), np.zeros((ny, nu))])
    return _closed(P, F, Gm, Hm, np.zeros((ny, nu)), sys1.inputs, sys1.outputs, "", "the feedback loop",
                   names_checked=True)


def _index(key: Any, names: tuple[str, ...], what: str) -> list[int]:
    n = len(names)
    if isinstance(key, slice):
        return list(range(n))[key]
    keys = [key] if isinstance(key, (str, numbers.Integral)) else key
    try:
        keys = list(keys)
    except TypeError:
        raise InvalidTypeError(f"{what} index must be an integer, a name, a slice or a list, got {plain(key)!r}") from None
    out = []
    for k in keys:
        if isinstance(k, str):
            if k not in names:
                raise InvalidValueError(f"no {what} named {k!r}; the {what}s are {list(names)}")
            out.append(names.index(k))
        elif isinstance(k, numbers.Integral) and not isinstance(k, bool):
            if not -n <= k < n:
                raise InvalidValueError(f"{what} index {k} is out of range for {n} {what}s")
            out.append(int(k) % n)
        else:
            raise InvalidTypeError(f"{what} index must be an integer or a name, got {plain(k)!r}")
    return out


def select(sys: DelayLTI, key: Any) -> DelayLTI:
    """``sys[outputs, inputs]``: the subsystem from some inputs to some outputs (by position or name).

    Examples
    --------
    >>> from delaykit import tf
    >>> G = tf([["exp(-s)/(s+1)", "2/(s+1)"], ["0", "1/(s+3)"]])
    >>> G[0, 1].dcgain().tolist()
    [[2.0]]
    """
    if not (isinstance(key, tuple) and len(key) == 2):
        raise InvalidTypeError(f"index a system as sys[outputs, inputs], got sys[{key!r}]")
    rows = _index(key[0], sys.outputs, "output")
    cols = _index(key[1], sys.inputs, "input")
    return DelayLTI._from_parts((sys.A, sys.B1[:, cols], sys.B2, sys.C1[rows], sys.C2, sys.D11[np.ix_(rows, cols)],
                                 sys.D12[rows], sys.D21[:, cols], sys.D22), sys.delays, sys.limits,
                                [sys.inputs[j] for j in cols], [sys.outputs[i] for i in rows], sys.name)


def summing_junction(inputs: Sequence[str], output: str, *, name: str = "") -> DelayLTI:
    """A static block ``output = sum of inputs``; an input written ``"-e"`` is subtracted (signal ``e``).

    Examples
    --------
    >>> summing_junction(["r", "-y"], "e").D11.tolist()
    [[1.0, -1.0]]
    >>> summing_junction(["r", "--y"], "e")
    Traceback (most recent call last):
    ...
    delaykit.errors.InvalidValueError: summing_junction: input '--y' must be a name with one sign at most (e, +e, -e)
    """
    if isinstance(inputs, str) or not isinstance(inputs, Sequence) or not inputs:
        raise InvalidTypeError(f"summing_junction: inputs must be a non-empty list of names, got {inputs!r}")
    signs, names = [], []
    for x in inputs:
        if not isinstance(x, str):
            raise InvalidTypeError(f"summing_junction: every input must be a name, optionally '-name', got {x!r}")
        term = x.strip()
        sign = term[:1] if term[:1] in ("-", "+") else ""
        name_ = term[len(sign):].strip()
        if not name_ or name_[0] in "-+":  # '--r', '+-y': one sign at most, never read as a product of signs
            raise InvalidValueError(f"summing_junction: input {x!r} must be a name with one sign at most (e, +e, -e)")
        signs.append(-1.0 if sign == "-" else 1.0)
        names.append(name_)
    return gain(np.array([signs]), inputs=names, outputs=[output], name=name)


def interconnect(blocks: Sequence[Any], inputs: Sequence[str], outputs: Sequence[str], *, name: str = ""
                 ) -> DelayLTI:
    """Blocks connected by the names of their signals, as python-control's ``interconnect``.

    Each block input is fed by the block output of the same name, or by the external input of that name.  Use
    :func:`summing_junction` for sums.

    Parameters
    ----------
    blocks : sequence of DelayLTI
        The blocks, each with named inputs and outputs; output names must be distinct over all blocks.
    inputs : sequence of str
        The external inputs, in order.
    outputs : sequence of str
        The external outputs (block outputs or external inputs), in order.
    name : str
        The label of the result.

    Raises
    ------
    InvalidValueError
        For a block input fed by nothing, or by both an external input and a block output, an output name used
        twice, an unknown external output, an external input that feeds nothing, or a loop that is not well posed.

    Examples
    --------
    A PI controller around the FOPDT ``12.8 e^{-s}/(16.7 s + 1)``:

    >>> from delaykit import tf
    >>> G = tf("12.8*exp(-s)/(16.7*s+1)", inputs="u", outputs="y")
    >>> C = tf("0.375*(1 + 1/(8.29*s))", inputs="e", outputs="u")
    >>> T = interconnect([G, C, summing_junction(["r", "-y"], "e")], inputs=["r"], outputs=["y"])
    >>> round(float(T.dcgain()[0, 0]), 12)
    1.0
    """
    if isinstance(blocks, DelayLTI) or not isinstance(blocks, Sequence) or not blocks:
        raise InvalidTypeError("interconnect: blocks must be a non-empty list of systems")
    bl = [as_system(b, f"block {k}") for k, b in enumerate(blocks)]
    try:
        ext_in = [inputs] if isinstance(inputs, str) else list(inputs)
        ext_out = [outputs] if isinstance(outputs, str) else list(outputs)
    except TypeError:
        raise InvalidTypeError(f"interconnect: inputs and outputs must be names or lists of names, got "
                               f"{reprlib.repr(inputs)} and {reprlib.repr(outputs)}") from None
    for label, names in (("inputs", ext_in), ("outputs", ext_out)):
        if any(not isinstance(x, str) for x in names):
            raise InvalidTypeError(f"interconnect: {label} must be names, got {names!r}")
        if len(set(names)) != len(names):
            raise InvalidValueError(f"interconnect: {label} {names} repeat a name")
    v = [(k, x) for k, b in enumerate(bl) for x in b.inputs]
    e = [x for b in bl for x in b.outputs]
    dup = sorted({x for x in e if e.count(x) > 1})
    if dup:
        raise InvalidValueError(f"interconnect: the block outputs {dup} are produced by more than one block; give "
                                "each signal one source (add the signals with a summing_junction)")
    F = np.zeros((len(v), len(e)))
    G = np.zeros((len(v), len(ext_in)))
    for i, (k, x) in enumerate(v):
        if x in e and x in ext_in:
            raise InvalidValueError(f"interconnect: the input {x!r} of block {k} ({bl[k].name or 'unnamed'}) is both "
                                    "an external input and a block output")
        if x in e:
            F[i, e.index(x)] = 1.0
        elif x in ext_in:
            G[i, ext_in.index(x)] = 1.0
        else:
            raise InvalidValueError(f"interconnect: the input {x!r} of block {k} ({bl[k].name or 'unnamed'}) is "
                                    f"connected to nothing (no block output or external input has that name)")
    unused = [x for j, x in enumerate(ext_in) if not G[:, j].any()]
    if unused:
        raise InvalidValueError(f"interconnect: the external inputs {unused} feed no block")
    H = np.zeros((len(ext_out), len(e)))
    J = np.zeros((len(ext_out), len(ext_in)))
    for r, x in enumerate(ext_out):
        if x in e:
            H[r, e.index(x)] = 1.0
        elif x in ext_in:
            J[r, ext_in.index(x)] = 1.0
        else:
            raise InvalidValueError(f"interconnect: the output {x!r} is no block's output nor an external input "
                                    f"(the signals are {sorted(set(e))})")
    return _closed(_stack(bl), F, G, H, J, ext_in, ext_out, name, "the interconnection")
