"""Optional dependencies: import one, or say in one line which extra of posekit installs it.

The core install runs the profiler, ceiling, localcal and seam pipelines; the rest comes with
extras (see pyproject.toml and the README): ``studies`` (Dask, statsmodels) and ``urdf``
(yourdfpy, lxml). Every lazy import of an optional package goes through :func:`require`.
"""

import importlib

from .errors import MissingExtraError

__all__ = ["require"]


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
        ``<what> needs the '<extra>' extra: pip install "posekit[<extra>]"`` on one line; when
        the package is there but one of its own imports fails, the import error follows.

    Examples
    --------
    >>> require("math", "studies", "nothing").sqrt(4.0)
    2.0
    """
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        msg = f"{what} needs the '{extra}' extra: pip install \"posekit[{extra}]\""
        if alternative:
            msg += f" (or {alternative})"
        missing = getattr(exc, "name", None) or ""
        top = module.split(".")[0]
        if missing.split(".")[0] != top:            # the package is there; something it imports is not
            msg += f"; {' '.join(str(exc).split())[:160]}"
        raise MissingExtraError(msg) from None
