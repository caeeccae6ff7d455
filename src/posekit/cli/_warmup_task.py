"""One task of ``posekit warmup``, run in its own process (:mod:`posekit.cli.warmup` starts it).

Apart from :mod:`~posekit.cli.warmup` because it runs the CLI's :func:`~posekit.cli.main.main`,
which imports the warm-up's parser: keeping the two in one module would close an import circle.
"""

import json
import tempfile

from .warmup import TASKS

__all__ = ["run_task"]


def run_task(name: str) -> None:
    """Run one warm-up task in this process; print ``{"task", "compiled", "error", "skipped"}`` as
    JSON (``skipped``: the task's system needs an extra that is not installed; not a failure)."""
    import contextlib
    import io

    from .. import _jit
    from .main import main

    commands = next(t[2] for t in TASKS if t[0] == name)
    error = None
    with tempfile.TemporaryDirectory(prefix="posekit-warmup-") as tmp:
        for argv in commands:
            argv = [a.replace("{tmp}", tmp) for a in argv]
            sink_out, sink_err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(sink_out), contextlib.redirect_stderr(sink_err):
                _jit.enable_compile_notice(quiet=True)
                code = main(argv)
            failure = [ln for ln in sink_err.getvalue().splitlines() if ln.startswith("posekit: error")]
            if code and failure:          # a batch with suspect items exits 1: that compiled all the same
                error = failure[-1].removeprefix("posekit: error: ")[:200]
                break
    skipped = error is not None and "extra: pip install" in error     # an extra not installed: nothing to warm
    print(json.dumps({"task": name, "compiled": _jit.compile_count(), "error": None if skipped else error,
                      "skipped": error if skipped else None}))
