"""System files: a delay system written as TOML, blocks and their connections by name.

A system file lists blocks, each with named inputs and outputs, and the system's external inputs and outputs;
the blocks are joined where a block input has the name of a block output (:func:`~delaykit.systems.algebra.\
interconnect`).  ``break`` names the signals where the loop is opened for its margins.

.. code-block:: toml

    name = "PI speed loop"
    inputs = ["v_ref"]
    outputs = ["v"]
    break = ["a"]                      # optional: margins with the loop opened at these signals

    [[blocks]]
    name = "vehicle"
    tf = "1/(0.3*s+1)"                 # text with exp(-T*s) factors, or a number (a gain)
    inputs = "a"
    outputs = "v"

    [[blocks]]
    ss = {A = [[0.0]], B = [[1.0]], C = [[4.0]], D = [[2.0]]}    # state-space matrices (lists of rows)
    inputs = ["ev"]
    outputs = ["a_req"]

    [[blocks]]
    delay = 0.05                       # a pure delay, s
    inputs = "a_req"
    outputs = "a"

    [[blocks]]
    sum = ["v_ref", "-v"]              # a summing junction ("-" subtracts)
    outputs = "ev"

A block may also be ``saturation = [lower, upper]`` (limits; TOML's ``inf`` for none, or a table such as
``{upper = 3.0}`` with a side left out), :func:`~delaykit.systems.build.saturation`.

Opening the loop at a signal ``x``: the block that outputs ``x`` now outputs ``x_out`` and ``x`` becomes an
external input; the loop transfer is ``L = -T(x -> x_out)`` (the other external inputs at zero), so that closing
``x = x_out`` is ``feedback(L, I)``, the convention of :func:`~delaykit.spectrum.systems.loop_margins`.

Every error names the file, the block and the bad value (:class:`~delaykit.errors.InvalidValueError`).

Examples
--------
>>> import os, tempfile
>>> text = '''inputs = ["r"]
... outputs = ["y"]
... break = ["u"]
... [[blocks]]
... tf = "exp(-0.5*s)/s"
... inputs = "u"
... outputs = "y"
... [[blocks]]
... sum = ["r", "-y"]
... outputs = "u"
... '''
>>> with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
...     _ = f.write(text)
>>> sf = read_system_file(f.name)
>>> sf.system
DelayLTI(1 input ['r'] -> 1 output ['y'], 1 state, delays [0.5] s)
>>> sf.loops[0]
DelayLTI(loop at u: 1 input ['u'] -> 1 output ['u_out'], 1 state, delays [0.5] s)
>>> os.unlink(f.name)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InvalidValueError, check_path
from ..models.loop import read_toml
from .algebra import interconnect, summing_junction
from .build import delay, saturation, ss, tf
from .lti import DelayLTI

__all__ = ["SystemFile", "read_system_file", "load_system", "system_from_dict"]

_MAX_BLOCKS = 1000
_MAX_DEPTH = 3  # a matrix is a list of rows of numbers: the deepest value a system file has
_TOP_KEYS = ("name", "inputs", "outputs", "break", "blocks")
_KINDS = ("tf", "ss", "delay", "sum", "saturation")
_BLOCK_KEYS = ("name", "inputs", "outputs") + _KINDS


@dataclass(frozen=True, repr=False)
class SystemFile:
    """A system read from a file: the interconnection, and the loops opened at its ``break`` signals.

    Attributes
    ----------
    system : DelayLTI
        The interconnection, from the file's ``inputs`` to its ``outputs``.
    breaks : tuple of str
        The signals where the loop is opened for margins (may be empty).
    loops : tuple of DelayLTI
        One SISO loop transfer ``L`` per break signal, each with the other breaks closed (loop-at-a-time).
    source : str
        The file's path (or ``"dict"``).
    """

    system: DelayLTI
    breaks: tuple[str, ...]
    loops: tuple[DelayLTI, ...]
    source: str

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {"source": self.source, "system": repr(self.system), "breaks": list(self.breaks)}

    def __repr__(self) -> str:
        at = f", loop opened at {', '.join(self.breaks)}" if self.breaks else ""
        return f"SystemFile({self.source}: {self.system!r}{at})"


def _where(source: str, what: str) -> str:
    return f"{source}: {what}"


def _depth(x: Any, level: int = 0) -> int:
    if isinstance(x, (list, tuple)):
        return max([_depth(v, level + 1) for v in x], default=level + 1)
    if isinstance(x, dict):
        return max([_depth(v, level + 1) for v in x.values()], default=level + 1)
    return level


def _names(source: str, where: str, value: Any, *, required: bool = True) -> list[str]:
    if value is None:
        if required:
            raise InvalidValueError(_where(source, f"{where} is missing (a signal name or a list of names)"))
        return []
    items = [value] if isinstance(value, str) else value
    if not isinstance(items, list) or not items or not all(isinstance(v, str) and v.strip() for v in items):
        raise InvalidValueError(_where(source, f"{where} must be a signal name or a non-empty list of names, got "
                                               f"{value!r}"))
    return [v.strip() for v in items]


def _number(source: str, where: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InvalidValueError(_where(source, f"{where} must be a number, got {value!r:.60}"))
    try:
        x = float(value)  # an integer of 400 digits: beyond the floats
    except OverflowError:
        raise InvalidValueError(_where(source, f"{where} must be finite, got an integer of "
                                               f"{len(str(abs(value)))} digits")) from None
    if not math.isfinite(x):
        raise InvalidValueError(_where(source, f"{where} must be finite, got {value!r}"))
    return x


def _matrix(source: str, where: str, value: Any) -> list[list[float]]:
    if not isinstance(value, list) or not all(isinstance(r, list) for r in value):
        raise InvalidValueError(_where(source, f"{where} must be a list of rows (lists of numbers), got {value!r}"))
    return [[_number(source, f"{where}[{i}][{j}]", x) for j, x in enumerate(r)] for i, r in enumerate(value)]


def _block(source: str, k: int, spec: Any) -> DelayLTI:
    if not isinstance(spec, dict):
        raise InvalidValueError(_where(source, f"blocks[{k}] must be a table, got {spec!r}"))
    label = spec.get("name", f"blocks[{k}]")
    if not isinstance(label, str):
        raise InvalidValueError(_where(source, f"blocks[{k}].name must be text, got {label!r}"))
    where = f"block {label!r}"
    unknown = sorted(set(spec) - set(_BLOCK_KEYS))
    if unknown:
        raise InvalidValueError(_where(source, f"{where}: unknown key {unknown[0]!r} (a block has "
                                               f"{', '.join(_BLOCK_KEYS)})"))
    kinds = [x for x in _KINDS if x in spec]
    if len(kinds) != 1:
        raise InvalidValueError(_where(source, f"{where} needs exactly one of {', '.join(_KINDS)}, got "
                                               f"{', '.join(kinds) or 'none'}"))
    kind = kinds[0]
    outs = _names(source, f"{where}: outputs", spec.get("outputs"))
    name = label if "name" in spec else ""
    if kind == "sum":
        terms = _names(source, f"{where}: sum", spec["sum"])
        if "inputs" in spec:
            raise InvalidValueError(_where(source, f"{where}: a sum block takes its inputs from 'sum', not 'inputs'"))
        if len(outs) != 1:
            raise InvalidValueError(_where(source, f"{where}: a sum block has one output, got {outs}"))
        return _made(source, where, summing_junction, terms, outs[0], name=name)
    ins = _names(source, f"{where}: inputs", spec.get("inputs"))
    if kind == "delay":
        return _made(source, where, delay, _number(source, f"{where}: delay", spec["delay"]), inputs=ins, outputs=outs,
                     name=name)
    if kind == "saturation":
        lo, hi = _limits(source, where, spec["saturation"])
        return _made(source, where, saturation, lo, hi, inputs=ins, outputs=outs, name=name)
    if kind == "tf":
        v = spec["tf"]
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            v = _number(source, f"{where}: tf", v)
        elif not isinstance(v, str):
            raise InvalidValueError(_where(source, f"{where}: tf must be text such as '2*exp(-0.5*s)/(s+1)' or a "
                                                   f"number, got {v!r}"))
        return _made(source, where, tf, v, inputs=ins, outputs=outs, name=name or None)
    m = spec["ss"]
    if not isinstance(m, dict):
        raise InvalidValueError(_where(source, f"{where}: ss must be a table with A, B, C, D, got {m!r}"))
    bad = sorted(set(m) - {"A", "B", "C", "D"})
    if bad:
        raise InvalidValueError(_where(source, f"{where}: ss has an unknown matrix {bad[0]!r} (A, B, C, D)"))
    for key in ("A", "B", "C"):
        if key not in m:
            raise InvalidValueError(_where(source, f"{where}: ss is missing the matrix {key}"))
    mats = {key: _matrix(source, f"{where}: ss.{key}", m[key]) for key in m}
    return _made(source, where, ss, mats["A"], mats["B"], mats["C"], mats.get("D"), inputs=ins, outputs=outs,
                 name=name)


def _limits(source: str, where: str, value: Any) -> tuple[float, float]:
    """``saturation = [lower, upper]`` (TOML's ``-inf``/``inf`` for no limit) or a table with ``lower`` and/or
    ``upper`` (an omitted side has no limit), with ``lower <= 0 <= upper`` and ``lower < upper``."""
    if isinstance(value, dict) and value and set(value) <= {"lower", "upper"}:
        pair = [value.get("lower", -math.inf), value.get("upper", math.inf)]
    elif isinstance(value, list) and len(value) == 2:
        pair = list(value)
    else:
        raise InvalidValueError(_where(source, f"{where}: saturation must be [lower, upper] or a table with lower "
                                               f"and/or upper, got {value!r}"))
    for x in pair:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or isinstance(x, float) and math.isnan(x):
            raise InvalidValueError(_where(source, f"{where}: saturation limits must be numbers (inf for no "
                                                   f"limit), got {x!r:.60}"))
    lo, hi = (x if isinstance(x, float) else _number(source, f"{where}: saturation limit", x) for x in pair)
    if not (lo <= 0.0 <= hi and lo < hi):
        raise InvalidValueError(_where(source, f"{where}: saturation must have lower <= 0 <= upper and lower < "
                                               f"upper (rest inside the limits), got [{lo:g}, {hi:g}]"))
    return lo, hi


def _made(source: str, where: str, make: Any, *args: Any, **kwargs: Any) -> DelayLTI:
    """``make(*args, **kwargs)``, its error (a bad transfer function, matrix or delay) prefixed by the file and the
    block."""
    try:
        return make(*args, **kwargs)
    except InvalidValueError as exc:
        raise InvalidValueError(_where(source, f"{where}: {exc}")) from None


def _named(sys: DelayLTI, outputs: list[str], name: str, inputs: list[str] | None = None) -> DelayLTI:
    """``sys`` with other signal names (``inputs`` None: its own) and label."""
    return DelayLTI(A=sys.A, B1=sys.B1, B2=sys.B2, C1=sys.C1, C2=sys.C2, D11=sys.D11, D12=sys.D12, D21=sys.D21,
                    D22=sys.D22, delays=sys.delays, limits=sys.limits, inputs=sys.inputs if inputs is None else inputs,
                    outputs=outputs, name=name)


def _interconnect(source: str, blocks: list[DelayLTI], inputs: list[str], outputs: list[str],
                  name: str) -> DelayLTI:
    known = {n for b in blocks for n in b.outputs} | set(inputs)
    for b in blocks:
        for n in b.inputs:
            if n not in known:
                raise InvalidValueError(_where(source, f"unknown signal {n!r} (an input of block "
                                                       f"{b.name or '?'!r}): no block outputs it and it is not "
                                                       "among the inputs"))
    for n in outputs:
        if n not in known:
            raise InvalidValueError(_where(source, f"unknown signal {n!r} among the outputs: no block outputs it"))
    try:
        return interconnect(blocks, inputs, outputs, name=name)
    except InvalidValueError as exc:
        raise InvalidValueError(_where(source, str(exc))) from None


def system_from_dict(data: Any, *, source: str = "dict") -> SystemFile:
    """A system from the parsed contents of a system file (see the module's text for the keys).

    Examples
    --------
    >>> sf = system_from_dict({"inputs": ["u"], "outputs": ["y"],
    ...                        "blocks": [{"tf": "2/(s+1)", "inputs": "u", "outputs": "y"}]})
    >>> float(sf.system.dcgain()[0, 0])
    2.0
    """
    if not isinstance(data, dict):
        raise InvalidValueError(_where(source, f"a system file is a table of keys, got {type(data).__name__}"))
    if _depth(data) > _MAX_DEPTH + 3:  # blocks[k].ss.A[i][j] is the deepest legitimate value
        raise InvalidValueError(_where(source, f"values are nested {_depth(data)} levels deep; a system file's "
                                               f"deepest value (blocks -> ss -> matrix rows) is {_MAX_DEPTH + 3}"))
    unknown = sorted(set(data) - set(_TOP_KEYS))
    if unknown:
        raise InvalidValueError(_where(source, f"unknown key {unknown[0]!r} (a system file has "
                                               f"{', '.join(_TOP_KEYS)})"))
    name = data.get("name", "")
    if not isinstance(name, str):
        raise InvalidValueError(_where(source, f"name must be text, got {name!r}"))
    inputs = _names(source, "inputs", data.get("inputs"))
    outputs = _names(source, "outputs", data.get("outputs"))
    breaks = _names(source, "break", data.get("break"), required=False)
    specs = data.get("blocks")
    if not isinstance(specs, list) or not specs:
        raise InvalidValueError(_where(source, "blocks is missing: give each block as a [[blocks]] table"))
    if len(specs) > _MAX_BLOCKS:
        raise InvalidValueError(_where(source, f"{len(specs)} blocks; at most {_MAX_BLOCKS}"))
    blocks = [_block(source, k, s) for k, s in enumerate(specs)]
    system = _interconnect(source, blocks, inputs, outputs, name)
    made = {n for b in blocks for n in b.outputs}
    loops = []
    for x in breaks:
        if x not in made:
            raise InvalidValueError(_where(source, f"unknown signal {x!r} in break: no block outputs it"))
        out = f"{x}_out"
        while out in made or out in inputs:
            out += "_"
        opened = [_named(b, [out if n == x else n for n in b.outputs], b.name) for b in blocks]
        T = _interconnect(source, opened, inputs + [x], [out], f"loop at {x}")
        loops.append(_named(-(T[0, len(inputs)]), [out], f"loop at {x}", inputs=[x]))
    return SystemFile(system, tuple(breaks), tuple(loops), source)


def read_system_file(path: str | Path) -> SystemFile:
    """Read a system file (TOML; see the module's text).

    Raises
    ------
    InvalidValueError
        For a file that cannot be read, is not TOML, or describes no valid system; the message names the file
        and the bad value.

    Examples
    --------
    See the module's.
    """
    data = read_toml(check_path("system file", path), "system file")  # (at most budget.MAX_CONFIG_BYTES)
    return system_from_dict(data, source=str(path))


def load_system(path: str | Path) -> DelayLTI:
    """The system of a system file: its blocks interconnected by name (see :func:`read_system_file`).

    Examples
    --------
    >>> import os, tempfile
    >>> with tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False) as f:
    ...     _ = f.write('inputs = "u"\\noutputs = "y"\\n[[blocks]]\\ntf = "exp(-s)/(s+1)"\\ninputs = "u"\\noutputs = "y"\\n')
    >>> load_system(f.name)
    DelayLTI(1 input ['u'] -> 1 output ['y'], 1 state, delays [1] s)
    >>> os.unlink(f.name)
    """
    return read_system_file(path).system
