"""``--config FILE`` and ``--dump-config`` for a verb whose parameters are its flags.

A verb that calls :func:`add_config_arguments` takes its parameters from a YAML file too: one key
per flag, named as the flag without its dashes (``noise_um: 5`` or ``noise-um: 5``; a positional
argument by its name, ``input: run.npz``; ``null`` is "not given"). Precedence: defaults < file < flags. Every value goes
through the flag's own parsing and range check, so a file value and the same flag fail alike,
and the message names the file and the key; an unknown key is an error that names it.
``--dump-config`` prints the effective parameters as YAML — loadable by ``--config`` — and exits 0
without running the verb (its required flags may then be missing).

:func:`apply_config` runs before argparse (``posekit.cli.main``): it finds the verb's parser from
the command words of ``argv``, reads the file into that parser's defaults and relaxes the
required flags the file gives (or all of them for ``--dump-config``); :func:`dump_config` prints.
"""

import argparse

from ..errors import ConfigError
from ._flags import _OutOfRange

__all__ = ["add_config_arguments", "apply_config", "dump_config", "config_keys", "wants_dump"]

_SKIP = {"help", "config", "dump_config", "version", "_flag_config"}


def add_config_arguments(parser: argparse.ArgumentParser) -> None:
    """Add ``--config FILE`` and ``--dump-config`` to a verb's parser."""
    parser.add_argument("--config", metavar="FILE", default=None,
                        help="YAML file of this command's parameters: one key per flag, named without the dashes "
                             "(noise_um: 5); flags given on the line win (defaults < file < flags)")
    parser.add_argument("--dump-config", action="store_true",
                        help="print the effective parameters as YAML (loadable by --config) and exit")
    parser.set_defaults(_flag_config=True)          # this verb's parameters are its flags (seam has its own)


def config_keys(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    """The verb's parameters: key (long flag without dashes, ``-`` as ``_``; a positional's name) → action."""
    keys = {}
    for action in parser._actions:
        if action.dest in _SKIP or action.help == argparse.SUPPRESS or isinstance(action, argparse._SubParsersAction):
            continue
        longs = [s for s in action.option_strings if s.startswith("--")]
        key = longs[0][2:].replace("-", "_") if longs else action.dest
        keys[key] = action
    return keys


def _leaf(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.ArgumentParser:
    """The parser of the verb named by the command words of ``argv`` (``profiler estimate``)."""
    current = parser
    for token in argv:
        subs = [a for a in current._actions if isinstance(a, argparse._SubParsersAction)]
        if subs and token in subs[0].choices:
            current = subs[0].choices[token]
    return current


def _option_value(argv: list[str], flag: str) -> str | None:
    for i, token in enumerate(argv):
        if token == flag and i + 1 < len(argv):
            return argv[i + 1]
        if token.startswith(flag + "="):
            return token[len(flag) + 1:]
    return None


def _convert(action: argparse.Action, key: str, value, source: str):
    """The file's value as the flag would parse it; a one-line ConfigError naming the file and key."""
    where = f"{source}: '{key}'"
    if isinstance(action, argparse._StoreConstAction):      # store_true/false/const: keyed by the flag
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if isinstance(action, argparse._AppendAction) or action.nargs in ("+", "*"):   # a list: one item per use
        items = value if isinstance(value, (list, tuple)) else [value]
        one = argparse.Action(action.option_strings, action.dest, type=action.type, choices=action.choices)
        return [_convert(one, key, v, source) for v in items]
    if value is None:
        raise ConfigError(f"{where}: expected a value, got null")
    if isinstance(value, (list, tuple)):
        text = ",".join(str(v) for v in value)
    elif isinstance(value, dict):
        raise ConfigError(f"{where}: expected a number, a string or a list, got a mapping")
    else:
        text = str(value).lower() if isinstance(value, bool) else str(value)
    if action.type is not None:
        try:
            parsed = action.type(text)
        except (argparse.ArgumentTypeError, TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: {exc}") from None
        if isinstance(parsed, _OutOfRange):
            raise ConfigError(f"{where}: {parsed.message}")
    else:
        parsed = text
    if action.choices is not None and parsed not in action.choices:
        raise ConfigError(f"{where}: expected one of {', '.join(map(str, action.choices))}, got {text[:80]!r}")
    return parsed


def apply_config(parser: argparse.ArgumentParser, argv: list[str]) -> None:
    """Before parsing ``argv``: the verb's ``--config`` file into its defaults, and ``--dump-config``'s
    relaxed required flags. A verb without ``--config`` is left alone."""
    leaf = _leaf(parser, argv)
    if not leaf._defaults.get("_flag_config"):
        return
    keys = config_keys(leaf)
    if "--dump-config" in argv:
        for action in keys.values():
            action.required = False
            if not action.option_strings and action.nargs is None:
                action.nargs = "?"                   # a positional argument may be missing too
            elif not action.option_strings and action.nargs == "+":
                action.nargs = "*"
    path = _option_value(argv, "--config")
    if path is None:
        return
    from ..io import load_yaml  # here, not above: --help and verbs without --config import no numpy
    data = load_yaml(path, expected="a YAML mapping of the command's parameters", error=ConfigError)
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a mapping of the command's parameters (key: value), got "
                          f"{type(data).__name__}")
    values = {}
    for raw, value in data.items():
        key = str(raw).replace("-", "_")
        action = keys.get(key)
        if action is None:
            known = ", ".join(sorted(keys))
            raise ConfigError(f"{path}: unknown key '{str(raw)[:60]}'; expected one of {known}"[:300])
        if value is None and action.default is None:
            continue                                 # null: not given (a required flag must then be given)
        value = _convert(action, key, value, path)
        # a store_false flag (--no-timestamps -> timestamps) is keyed by its flag: true means "given"
        if isinstance(action, argparse._StoreFalseAction):
            value = not value
        elif isinstance(action, argparse._StoreConstAction) and not isinstance(action, argparse._StoreTrueAction):
            if not value:
                continue                             # --ransac / --no-ransac: false is "not given"
            value = action.const
        if isinstance(action, argparse._AppendAction):
            action.__class__ = _FileAppend           # a flag given on the line replaces the file's list
            action.file_default = value
        values[action.dest] = value
        action.required = False
        if not action.option_strings and action.nargs is None:
            action.nargs = "?"
        elif not action.option_strings and action.nargs == "+":
            action.nargs = "*"                       # IMAGE ...: the file's list unless the line gives some
    leaf.set_defaults(**values)


class _FileAppend(argparse._AppendAction):
    """A repeated flag whose default came from ``--config``: its first use on the line starts a new list
    (flags win over the file) instead of appending to the file's."""

    file_default = None

    def __call__(self, parser, namespace, values, option_string=None):
        if getattr(namespace, self.dest, None) is self.file_default:
            setattr(namespace, self.dest, [])
        super().__call__(parser, namespace, values, option_string)


def dump_config(parser: argparse.ArgumentParser, argv: list[str], args) -> str:
    """The effective parameters of the verb of ``argv`` as YAML (``--dump-config``)."""
    import yaml

    out = {}
    for key, action in config_keys(_leaf(parser, argv)).items():
        value = getattr(args, action.dest, None)
        if isinstance(value, _OutOfRange):
            value = float(value) if isinstance(value, float) else int(value)
        if isinstance(action, argparse._StoreFalseAction):
            value = not value                        # keyed by the flag: true means "--no-x given"
        elif isinstance(action, argparse._StoreConstAction) and not isinstance(action, argparse._StoreTrueAction):
            value = value is not None and value == action.const     # --ransac/--no-ransac: true = given
        elif isinstance(action, argparse._AppendAction) and value is not None:
            value = list(value)
        out[key] = value
    return yaml.safe_dump(out, sort_keys=False, allow_unicode=True)


def wants_dump(args) -> bool:
    """Whether the parsed ``args`` asked a flag-configured verb for ``--dump-config``."""
    return bool(getattr(args, "_flag_config", False) and getattr(args, "dump_config", False))

