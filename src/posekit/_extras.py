"""Optional dependencies: import one, or say in one line which extra of posekit installs it.

The core install runs the profiler and seam pipelines and ``posekit localcal match``; the rest
comes with extras (see pyproject.toml and the README): ``vision`` (OpenCV: the ceiling system,
the localcal camera simulator, image reading and the profiler's OpenCV camera peer),
``studies`` (Dask, statsmodels) and ``urdf`` (yourdfpy, lxml). Every import of an optional
package goes through :func:`require`, or :func:`lazy` for a module-level name.
"""

import importlib

from .errors import MissingExtraError

__all__ = ["install_hint", "lazy", "require"]


def _checkout() -> bool:
    """True when posekit runs from a source checkout (``pip install -e .`` or ``PYTHONPATH=src``):
    its package folder sits in ``src/`` beside the project's pyproject.toml."""
    from pathlib import Path

    pyproject = Path(__file__).resolve().parents[2] / "pyproject.toml"
    try:
        return pyproject.is_file() and 'name = "posekit"' in pyproject.read_text(encoding="utf-8")
    except OSError:
        return False


def install_hint(extra: str) -> str:
    """The pip command that installs ``extra`` the way posekit was installed.

    ``pip install -e ".[extra]"`` in a source checkout (run from its root), ``pip install
    "posekit[extra]"`` for an installed package.

    Examples
    --------
    >>> install_hint("vision") in ('pip install -e ".[vision]"', 'pip install "posekit[vision]"')
    True
    """
    return f'pip install -e ".[{extra}]"' if _checkout() else f'pip install "posekit[{extra}]"'


def require(module: str, extra: str, what: str, *, alternative: str = ""):
    """The imported ``module``, or a :class:`~posekit.errors.MissingExtraError` naming ``extra``.

    Parameters
    ----------
    module : str
        Dotted module name, e.g. ``"statsmodels.api"``.
    extra : str
        The posekit extra that installs it, e.g. ``"studies"``.
    what : str
        What needs it, the start of the message, e.g. ``"posekit seam study"``.
    alternative : str, optional
        A way around the missing package, appended in parentheses.

    Returns
    -------
    module

    Raises
    ------
    MissingExtraError
        ``<what> needs the '<extra>' extra: <install_hint(extra)>`` on one line; when the
        package is there but one of its own imports fails, the import error follows.

    Examples
    --------
    >>> require("math", "studies", "nothing").sqrt(4.0)
    2.0
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        msg = f"{what} needs the '{extra}' extra: {install_hint(extra)}"
        if alternative:
            msg += f" (or {alternative})"
        missing = getattr(exc, "name", None) or ""
        top = module.split(".")[0]
        if missing.split(".")[0] != top:            # the package is there; something it imports is not
            msg += f"; {' '.join(str(exc).split())[:160]}"
        raise MissingExtraError(msg) from None


class _Lazy:
    """A module imported on first attribute access, through :func:`require`."""

    def __init__(self, module: str, extra: str, what: str):
        self._spec = (module, extra, what)
        self._module = None

    def __getattr__(self, name):
        if self._module is None:
            self._module = require(*self._spec)
        return getattr(self._module, name)


def lazy(module: str, extra: str, what: str):
    """A stand-in for ``import module`` at the top of a file: importing the file works without
    the extra, and the first use of the module raises the one-line MissingExtraError."""
    return _Lazy(module, extra, what)
