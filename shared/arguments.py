"""The command line's parser: argparse's, whose mistakes are named in the command they were made in.

argparse leaves an argument no sub-command knows to the top parser, so ``foresight eval interference --quick`` said
``foresight eval: error: unrecognized arguments: --quick``, naming neither the command that refused it nor what was
meant. :class:`ArgumentParser` names the sub-command that was given it, the closest option it has (``--robot-sped``:
did you mean ``--robot-speed``?), the sibling commands that have the option itself (``--quick``: an option of
``foresight eval all``) and the closest choice to a misspelt one (``foresight log inf``: did you mean ``info``?).
Sub-parsers made with ``add_subparsers`` are of the same class.
"""

from __future__ import annotations

import argparse
import sys
import typing
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from shared.config_names import closest

__all__ = ["ArgumentParser", "DefaultsHelpFormatter", "path_arg"]


class DefaultsHelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """The description as written, each option's default after its help (``bench faults`` and ``soak``: none)."""


def path_arg(text: str) -> Path:
    """A path given on the command line; an empty one is refused (it was the current directory).

    ``foresight security init ''`` wrote the authority's key into the working directory, ``log render --all --out ''``
    its PNGs, ``eval all --out ''`` its run.
    """
    if not text.strip():
        raise argparse.ArgumentTypeError("empty; give a path (an empty one would be the current directory)")
    return Path(text)


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose unrecognized arguments are refused by the sub-command given them.

    Options are never abbreviated (argparse's default takes a unique prefix: ``--compar`` ran ``--compare``'s three
    runs, and a prefix that a later option makes ambiguous would break a script), and a mistake is one line, not the
    command's whole usage before it (18 lines for ``foresight demo``).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def add_argument(self, *args: Any, **kwargs: Any) -> argparse.Action:
        """As argparse's; a ``type=Path`` argument refuses an empty path (:func:`path_arg`)."""
        if kwargs.get("type") is Path:
            kwargs["type"] = path_arg
        return super().add_argument(*args, **kwargs)

    def error(self, message: str) -> typing.NoReturn:
        """Exit with status 2 after one line: ``<prog>: error: <message>`` (``--help`` gives the usage)."""
        self.exit(2, f"{self.prog}: error: {message}\n")

    def _check_value(self, action: argparse.Action, value: Any) -> None:
        """As argparse's; a value that is none of the choices names the closest one (``log inf``: did you mean info?).

        argparse checks every value of an action with choices here, sub-commands included, and said only ``invalid
        choice: 'inf' (choose from ...)`` where the top level (``foresight demoo``) suggested ``demo``.
        """
        try:
            super()._check_value(action, value)
        except argparse.ArgumentError:
            choices = [str(c) for c in action.choices or ()]
            close = closest(value, choices) if isinstance(value, str) else ""
            if not close:
                raise
            raise argparse.ArgumentError(action, f"invalid choice: {value!r} ({close.removeprefix('; ')} choose from "
                                                 f"{', '.join(choices)})") from None

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """As argparse's; an unrecognized argument is an error of the command it was given to, with hints.

        That is the deepest sub-command named before it (``foresight log --bogus info``: ``foresight log``'s).
        """
        argv = list(sys.argv[1:] if args is None else args)
        ns, extras = self.parse_known_args(argv, namespace)
        if extras:
            before = argv[:argv.index(extras[0])] if extras[0] in argv else argv
            blamed, siblings = self, {}
            for parser, others, name in self.chain(ns):
                if name in before:
                    blamed, siblings = parser, others
            blamed.error(blamed.unrecognized(extras, siblings))
        return ns

    def chain(self, ns: argparse.Namespace) -> list[tuple[ArgumentParser, dict[str, ArgumentParser], str]]:
        """The sub-commands ``ns`` chose, outermost first: ``(parser, its siblings by name, its name)``."""
        for action in self._actions:
            parsers = getattr(action, "choices", None)
            if action.option_strings or not isinstance(parsers, dict):
                continue
            name = getattr(ns, action.dest, None)
            child = parsers.get(name)
            if isinstance(child, ArgumentParser):
                siblings = {n: p for n, p in parsers.items() if p is not child and isinstance(p, ArgumentParser)}
                return [(child, siblings, str(name)), *child.chain(ns)]
        return []

    def option_names(self) -> list[str]:
        """Every option string this parser takes (``--help`` included)."""
        return [s for action in self._actions for s in action.option_strings]

    def unrecognized(self, extras: list[str], siblings: dict[str, Any] | None = None) -> str:
        """The error for ``extras``: each unknown option's closest option here, or the siblings that have it."""
        hints = []
        mine = self.option_names()
        for token in extras:
            if not token.startswith("-") or token == "-":
                continue
            name = token.split("=", 1)[0]
            zenoh = "--zenoh-" + name.removeprefix("--")  # --mode is the services' own; elsewhere the session's
            # the options' common "--" left out of the likeness (closest's prefix): --bogus was "close" to --ros2
            close = f"did you mean {zenoh}?" if zenoh in mine else closest(name, mine, prefix="--")
            if close:
                hints.append(close.removeprefix("; "))
                continue
            owners = [p.prog for p in (siblings or {}).values() if name in p.option_names()]
            if owners:
                hints.append(f"{name} is an option of {', '.join(owners)}")
        text = f"unrecognized arguments: {' '.join(extras)}"
        return text + (f" ({'; '.join(hints)})" if hints else f" (see {self.prog} --help)")
