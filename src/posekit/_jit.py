"""How posekit compiles its hot kernels: numba's ``njit`` with a disk cache every user can write.

Every kernel module takes ``njit`` from here instead of from numba (same arguments; ``cache``
is always on), so the place and the policy of the compiled-code cache are decided once, here.

Where compiled kernels are stored (the first that can be written wins, per kernel module):

1. ``POSEKIT_CACHE_DIR`` (created if needed) -- a user's or an administrator's choice;
2. ``NUMBA_CACHE_DIR``, numba's own setting;
3. ``__pycache__`` beside the module (numba's default) when the package folder is writable;
4. the user's cache folder, :func:`user_cache_dir` (``~/.cache/posekit/numba`` on Linux);
5. ``posekit-<uid>/numba`` in the temporary folder, if it is the user's own.

With none of them writable, kernels compile in every process (one note on stderr says so).
A kernel whose package folder is read-only still loads what was compiled into its
``__pycache__`` when the folder was writable (``posekit warmup`` run once by whoever installed
posekit), and compiles into the user's folder only what is missing there.

Compilation costs: numba types and optimises every kernel once per signature; on a 2-core
machine the first run of a system takes tens of seconds (``FIRST_COMPILE_S``). A failed
slice assignment inside a kernel raises ``ValueError("cannot assign slice from input of
different size")``, numba's message without the two shapes: the shapes' message makes
numba compile its string formatting (a quarter of the profiler's compile time) into every
process that compiles a kernel, for an error that the checks at the public edge keep from
ever happening.
"""

import abc
import inspect
import os
import sys
import tempfile
import threading
import time

import numba
from numba.core import caching
from numba.core import event as _event

__all__ = ["njit", "cache_dir", "user_cache_dir", "kernels", "enable_compile_notice", "compile_count",
           "CACHE_ENV", "FIRST_COMPILE_S"]

#: Environment variable that chooses the folder of compiled kernels.
CACHE_ENV = "POSEKIT_CACHE_DIR"

#: CPU seconds a system's kernels take to compile in one process (2-core machine, cold cache):
#: CPU time of ``posekit demo`` / ``posekit seam demo`` / ``posekit ceiling demo --duration-s 1``
#: / ``posekit localcal demo --camera-hz 1 --plot-hz 0`` with an empty cache minus that of the
#: same command with a warm one (36.1 - 7.5, 26.2 - 2.3, 8.7 - 4.7, 8.9 - 2.1 s; see
#: docs/notes/issue-30-startup.md). The first-compile note quotes them; a busy machine takes longer.
FIRST_COMPILE_S = {"profiler": 30, "seam": 25, "ceiling": 5, "localcal": 7}

_KERNELS = []             # every dispatcher made by njit, in definition order
_NOTES = set()            # one-off notes already printed


def user_cache_dir() -> str:
    """The platform's per-user cache folder for posekit's kernels (``$XDG_CACHE_HOME/posekit/numba``
    or ``~/.cache/posekit/numba`` on Linux, ``~/Library/Caches/posekit/numba`` on macOS,
    ``%LOCALAPPDATA%\\posekit\\Cache\\numba`` on Windows)."""
    from numba.misc.appdirs import AppDirs

    return os.path.join(AppDirs(appname="posekit", appauthor=False).user_cache_dir, "numba")


def _temp_cache_dir() -> str | None:
    """``<tmp>/posekit-<uid>/numba`` when that folder is (or can be made) the user's own and
    closed to others -- cached code is loaded and run, so never from a folder another user owns."""
    uid = os.getuid() if hasattr(os, "getuid") else None
    top = os.path.join(tempfile.gettempdir(), f"posekit-{uid if uid is not None else os.getlogin()}")
    try:
        os.makedirs(top, mode=0o700, exist_ok=True)
        st = os.lstat(top)
    except OSError:
        return None
    if uid is not None and (st.st_uid != uid or st.st_mode & 0o022 or not os.path.isdir(top)
                            or os.path.islink(top)):
        return None
    return os.path.join(top, "numba")


_CacheLocator = getattr(caching, "_CacheLocator")
_SourceMixin = getattr(caching, "_SourceFileBackedLocatorMixin")
_UserProvided = getattr(caching, "UserProvidedCacheLocator", None) or getattr(caching, "_UserProvidedCacheLocator")
_InTree = getattr(caching, "InTreeCacheLocator", None) or getattr(caching, "_InTreeCacheLocator")


class _RootLocator(_SourceMixin, _CacheLocator):
    """Kernels of one source folder in ``<root>/<folder name>_<hash of its path>`` (numba's layout
    under ``NUMBA_CACHE_DIR``), for a root that subclasses give."""

    @staticmethod
    @abc.abstractmethod
    def _root() -> str | None:
        """The folder under which this locator keeps kernels, or None when it cannot."""

    def __init__(self, py_func, py_file, root):
        self._py_file = py_file
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = os.path.join(root, self.get_suitable_cache_subpath(py_file))

    def get_cache_path(self):
        return self._cache_path

    @classmethod
    def from_function(cls, py_func, py_file):
        root = cls._root()
        if not root or not os.path.exists(py_file):
            return None
        self = cls(py_func, py_file, root)
        try:
            self.ensure_cache_path()
        except OSError:
            return None
        return self


class _EnvLocator(_RootLocator):
    @staticmethod
    def _root():
        return os.environ.get(CACHE_ENV) or None


class _UserLocator(_RootLocator):
    _root = staticmethod(user_cache_dir)


class _TempLocator(_RootLocator):
    _root = staticmethod(_temp_cache_dir)


class _Impl(caching.CompileResultCacheImpl):
    _locator_classes = [_EnvLocator, _UserProvided, _InTree, _UserLocator, _TempLocator]


class _Cache(caching.FunctionCache):
    """numba's function cache with posekit's locators, reading also the (read-only) in-tree cache."""

    _impl_class = _Impl

    def __init__(self, py_func):
        super().__init__(py_func)
        self._fallback = None
        in_tree = os.path.join(os.path.dirname(os.path.abspath(inspect.getfile(py_func))), "__pycache__")
        if os.path.abspath(self._cache_path) != in_tree and os.path.isdir(in_tree):
            self._fallback = caching.IndexDataCacheFile(cache_path=in_tree, filename_base=self._impl.filename_base,
                                                        source_stamp=self._impl.locator.get_source_stamp())

    def _load_overload(self, sig, target_context):
        data = super()._load_overload(sig, target_context)
        if data is None and self._enabled and self._fallback is not None:
            try:
                raw = self._fallback.load(self._index_key(sig, target_context.codegen()))
            except Exception:          # an unreadable or foreign index: compile instead
                raw = None
            if raw is not None:
                data = self._impl.rebuild(target_context, raw)
        return data


def _note(key: str, text: str) -> None:
    if key not in _NOTES:
        _NOTES.add(key)
        print(f"posekit: note: {text}", file=sys.stderr)


def njit(*args, **options):
    """``numba.njit`` with posekit's cache (``cache=`` is ignored: always on, see the module).

    Used as ``@njit`` or ``@njit(nogil=True, ...)``; the dispatcher is numba's.
    """
    options.pop("cache", None)

    def wrap(fn):
        disp = numba.njit(**options)(fn)
        try:
            disp._cache = _Cache(disp.py_func)
        except (RuntimeError, OSError):     # no writable place at all: compile in every process
            _note("nocache", f"no writable folder for compiled kernels (set {CACHE_ENV}); they compile on every run")
        _KERNELS.append(disp)
        return disp

    if len(args) == 1 and callable(args[0]) and not options:
        return wrap(args[0])
    if args:                               # an explicit signature: numba's own form
        return numba.njit(*args, cache=True, **options)
    return wrap


def kernels() -> list:
    """Every kernel made by :func:`njit` so far (the modules imported), numba dispatchers."""
    return list(_KERNELS)


def cache_dir(kernel=None) -> str:
    """Where compiled kernels go: the folder of ``kernel``'s cache, or for this installation
    the first folder of the list in the module that can be written (in the package tree:
    ``.../posekit/**/__pycache__``)."""
    if kernel is not None and getattr(kernel._cache, "cache_path", None):
        path = kernel._cache.cache_path
        return path if path.endswith("__pycache__") else os.path.dirname(path)
    for cls in _Impl._locator_classes:
        locator = cls.from_function(cache_dir, __file__)
        if locator is not None:
            if cls is _InTree:
                return os.path.join(os.path.dirname(os.path.abspath(__file__)), "**", "__pycache__")
            return os.path.dirname(locator.get_cache_path())
    return "nowhere (no writable folder)"


def _patch_shape_message() -> None:
    """Compile slice-assignment errors without numba's shape formatting (see the module)."""
    try:
        from numba.core.extending import overload
        from numba.np import arrayobj
    except ImportError:
        return
    if not hasattr(arrayobj, "raise_with_shape_context"):
        return

    def raise_with_shape_context(src_shapes, index_shape):
        raise ValueError("cannot assign slice from input of different size")

    @overload(raise_with_shape_context)
    def _raise(src_shapes, index_shape):
        def impl(src_shapes, index_shape):
            raise ValueError("cannot assign slice from input of different size")
        return impl

    arrayobj.raise_with_shape_context = raise_with_shape_context


_patch_shape_message()


# --- the first-compile note ------------------------------------------------------------------

class _CompileListener(_event.Listener):
    """Counts top-level compilations of posekit kernels; the first one prints the note (once per
    process) and, on a terminal, starts a progress bar of the kernels compiled."""

    def __init__(self, system: str | None, quiet: bool):
        self.system = system
        self.quiet = quiet
        self.depth = threading.local()
        self.count = 0
        self.bar = None
        self.t0 = None

    def on_start(self, event):
        depth = getattr(self.depth, "n", 0)
        self.depth.n = depth + 1
        if depth or not _is_posekit(event):
            return
        if self.t0 is None:
            self.t0 = time.perf_counter()
            if not self.quiet:
                self._announce(event)

    def on_end(self, event):
        self.depth.n = max(getattr(self.depth, "n", 1) - 1, 0)
        if self.depth.n or not _is_posekit(event):
            return
        self.count += 1
        if self.bar is not None:
            self.bar.update(1)

    def _announce(self, event):
        module = event.data["dispatcher"].py_func.__module__
        system = self.system if self.system in FIRST_COMPILE_S else module.split(".")[1]
        eta = FIRST_COMPILE_S.get(system)
        about = f"about {eta} s on an idle core" if eta else "up to half a minute per system"
        line = (f"posekit: compiling the {system} numba kernels on first use ({about}, once per install or upgrade; "
                f"cached in {cache_dir(event.data['dispatcher'])}); `posekit warmup` does it ahead of time")
        if not sys.stderr.isatty():
            print(line, file=sys.stderr, flush=True)
            return
        from tqdm import tqdm
        tqdm.write(line, file=sys.stderr)        # above any progress bar the command already shows
        self.bar = tqdm(file=sys.stderr, leave=False, bar_format="compiling kernels: {n} done [{elapsed}]")

    def close(self):
        if self.bar is not None:
            self.bar.close()
            self.bar = None


def _is_posekit(event) -> bool:
    disp = event.data.get("dispatcher")
    return disp is not None and getattr(disp.py_func, "__module__", "").startswith("posekit.")


_LISTENER = None


def enable_compile_notice(system: str | None = None, *, quiet: bool = False) -> None:
    """Print one line on stderr when a posekit kernel first compiles in this process (with a
    progress bar on a terminal) and count the kernels compiled (:func:`compile_count`).

    ``system`` names whose first-compile time the line quotes; ``quiet`` (or the environment
    variable ``POSEKIT_COMPILE_NOTICE=0``, which the test suite sets) only counts.
    """
    global _LISTENER
    quiet = quiet or os.environ.get("POSEKIT_COMPILE_NOTICE", "1") == "0"
    if _LISTENER is None:
        _LISTENER = _CompileListener(system, quiet)
        _event.register("numba:compile", _LISTENER)
        import atexit
        atexit.register(_LISTENER.close)
    else:
        _LISTENER.system, _LISTENER.quiet = system, quiet


def compile_count() -> int:
    """Top-level compilations of posekit kernels seen since :func:`enable_compile_notice`."""
    return 0 if _LISTENER is None else _LISTENER.count
