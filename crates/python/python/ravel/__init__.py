"""ravel from Python: check, verify and certify reach-avoid specs of neural
feedback loops with the same library the ``ravel`` command line runs.

A spec is given as a path (``str`` or ``os.PathLike``) or as its text
(``text=``, its relative paths read from ``directory=``, by default the
working folder). A controller, when given, replaces the spec's own: a path,
or the ONNX model's bytes (``bytes``, ``bytearray`` or ``memoryview``), e.g.
a model exported into memory in a training loop::

    report = ravel.verify("specs/double_integrator.ravel", controller=onnx_bytes)
    if report.verdict == "VERIFIED":
        ...

Every problem with a spec, a controller or an argument raises
:class:`RavelError`, carrying the diagnostic's code, message, span and hint.
The analysis runs with the GIL released: other Python threads go on.
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, List, Optional, Union

import numpy as np

from . import _ravel

__all__ = [
    "RavelError",
    "Report",
    "check",
    "verify",
    "certify",
    "MAX_SPEC_BYTES",
    "MAX_CONTROLLER_BYTES",
]

RavelError = _ravel.RavelError
RavelError.__doc__ = """A spec, controller or argument ravel cannot use.

``str(error)`` is the command line's rendering of the diagnostics (without
colours or control characters). Attributes, of the first diagnostic:

* ``code``: its stable code (``"E0102"``), or ``None`` for an unreadable
  file or a bad argument, which have no code;
* ``message``, ``label`` and ``hint`` (``hint`` may be ``None``);
* ``span``: ``None``, or a dict with the byte offsets ``start`` and ``end``
  in the spec's text and the 1-based ``line``, ``column``, ``end_line`` and
  ``end_column`` (columns in characters);
* ``diagnostics``: every diagnostic, each a dict with these keys.
"""

#: The largest spec, in bytes (``ravel_base::limits::MAX_SPEC_BYTES``).
MAX_SPEC_BYTES: int = _ravel.MAX_SPEC_BYTES
#: The largest controller, in bytes (``ravel_base::limits::MAX_CONTROLLER_BYTES``).
MAX_CONTROLLER_BYTES: int = _ravel.MAX_CONTROLLER_BYTES

PathLike = Union[str, "os.PathLike[str]"]
Controller = Union[PathLike, bytes, bytearray, memoryview, None]


def _spec_args(spec: Optional[PathLike], text: Optional[str], directory: Optional[PathLike]):
    if spec is not None and text is not None:
        raise TypeError("give the spec as a path or as text=, not both")
    if spec is None and text is None:
        raise TypeError("give the spec as a path or as text=")
    if spec is not None:
        if isinstance(spec, (bytes, bytearray)):
            raise TypeError("a spec path is a str or os.PathLike; give a spec's text as text=")
        spec = os.fspath(spec)
    elif not isinstance(text, str):
        raise TypeError("text= is the spec's text, a str")
    return spec, text, None if directory is None else os.fspath(directory)


def _controller_args(controller: Controller):
    if controller is None:
        return None, None
    if isinstance(controller, bytes):
        return None, controller
    if isinstance(controller, (bytearray, memoryview)):
        return None, bytes(controller)
    return os.fspath(controller), None


def check(
    spec: Optional[PathLike] = None,
    *,
    text: Optional[str] = None,
    directory: Optional[PathLike] = None,
    controller: Controller = None,
) -> str:
    """Parse and check a spec with its controller, as ``ravel check`` does.

    Returns the kind of spec, ``"system"`` (a closed loop) or ``"network"``
    (a network on its own); raises :class:`RavelError` with every
    diagnostic otherwise.
    """
    path, text, directory = _spec_args(spec, text, directory)
    cpath, cbytes = _controller_args(controller)
    return _ravel.check((path, text, directory), cpath, cbytes)


class Report:
    """The result of :func:`verify`.

    * ``json``: the report, as ``ravel verify --format json`` prints it,
      parsed (dicts, lists, numbers; no timing);
    * ``verdict``: ``"VERIFIED"``, ``"FALSIFIED"`` or ``"UNSURE"``;
    * ``lower``, ``upper``: ``float64`` arrays. For a closed loop, the
      reachable set's bounding box at every step, shape ``(steps + 1, n)``
      (row 0 is the initial set); for a network spec, the output set's
      bounding box, shape ``(m,)`` (``None`` when the output shape has
      none);
    * ``cell_lower``, ``cell_upper``: for a closed loop, each partition
      cell's box at every step, shape ``(cells, steps + 1, n)``; for a
      network spec, the input partition's cells, shape ``(cells, n)``;
    * ``certificate``: the ``ravel-certificate/1`` document (a dict) when
      asked for with ``certificate=True``, else ``None``.

    Bounds are sound for the real-arithmetic loop: a set that overflowed or
    that the time limit cut is the whole space (infinite bounds).
    ``report["key"]`` reads the JSON report.
    """

    def __init__(self, report: Dict[str, Any], arrays: Dict[str, np.ndarray], certificate):
        self.json: Dict[str, Any] = report
        self.verdict: str = report["verdict"]
        self.lower: Optional[np.ndarray] = arrays.get("lower")
        self.upper: Optional[np.ndarray] = arrays.get("upper")
        self.cell_lower: np.ndarray = arrays["cell_lower"]
        self.cell_upper: np.ndarray = arrays["cell_upper"]
        self.certificate: Optional[Dict[str, Any]] = certificate

    def __getitem__(self, key: str) -> Any:
        return self.json[key]

    def __repr__(self) -> str:
        return f"<ravel.Report {self.json.get('spec')!r}: {self.verdict}>"


def _array(data: bytes, shape) -> np.ndarray:
    a = np.frombuffer(data, dtype="<f8").reshape(tuple(shape))
    # a copy of its own, writeable, in the machine's byte order
    return a.astype(np.float64, copy=True)


def verify(
    spec: Optional[PathLike] = None,
    *,
    text: Optional[str] = None,
    directory: Optional[PathLike] = None,
    controller: Controller = None,
    time_limit: Optional[float] = None,
    jobs: Optional[int] = None,
    certificate: bool = False,
) -> Report:
    """Verify a spec, as ``ravel verify`` does, and return its :class:`Report`.

    ``time_limit`` (seconds) stops the analysis soundly (what it did not
    reach is UNSURE); ``jobs`` is the number of threads (default: the
    cores); ``certificate=True`` also builds the run's certificate
    (``Report.certificate``), which :func:`certify` re-checks. The GIL is
    released while the front end and the analysis run.
    """
    path, text, directory = _spec_args(spec, text, directory)
    cpath, cbytes = _controller_args(controller)
    if time_limit is not None:
        time_limit = float(time_limit)
    if jobs is not None:
        if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
            raise _argument_error("jobs must be a whole number, at least 1")
    report, arrays, cert = _ravel.verify(
        (path, text, directory), cpath, cbytes, time_limit, jobs, bool(certificate)
    )
    return Report(
        json.loads(report),
        {name: _array(data, shape) for name, data, shape in arrays},
        None if cert is None else json.loads(cert),
    )


def _argument_error(message: str) -> RavelError:
    e = RavelError(message)
    e.code = None
    e.message = message
    e.label = None
    e.hint = None
    e.span = None
    e.diagnostics = []
    return e


def certify(
    certificate: Union[PathLike, Dict[str, Any], bytes, bytearray],
    *,
    spec: Optional[PathLike] = None,
    text: Optional[str] = None,
    directory: Optional[PathLike] = None,
    controller: Controller = None,
) -> Dict[str, Any]:
    """Re-check a certificate, as ``ravel certify`` does.

    ``certificate`` is a path to a certificate file, the certificate itself
    (a dict, as ``Report.certificate``) or its JSON text as ``bytes``. The
    spec (a path, or ``text=``) and the controller (a path or bytes) default
    to the paths the certificate records, relative to the certificate
    file's folder (to the working folder for a certificate in memory).

    Returns a dict: ``answer`` (``"VALID"``, ``"INVALID"``,
    ``"UNSUPPORTED"`` or ``"UNREADABLE"``), ``reason`` (why, or ``None``),
    ``cells`` and ``steps`` checked (``subproblems``: the nodes of a
    network's activation-split tree), ``properties`` (one line per
    property) and ``spec_text_differs`` (the spec's text is not the
    certified one; its problem may still be). A spec or controller that
    does not check raises :class:`RavelError`.
    """
    cert_path, data = None, None
    if isinstance(certificate, dict):
        data = json.dumps(certificate).encode()
    elif isinstance(certificate, (bytes, bytearray, memoryview)):
        data = bytes(certificate)
    else:
        cert_path = os.fspath(certificate)
    if spec is not None and text is not None:
        raise TypeError("give the spec as a path or as text=, not both")
    spec_path = None if spec is None else os.fspath(spec)
    cpath, cbytes = _controller_args(controller)
    spec_args = (spec_path, text, None if directory is None else os.fspath(directory))
    return _ravel.certify(cert_path, data, spec_args, cpath, cbytes)
