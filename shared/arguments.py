"""The command line's parser: argparse's, whose mistakes are named in the command they were made in.

argparse leaves an argument no sub-command knows to the top parser, so ``foresight eval interference --quick`` said
``foresight eval: error: unrecognized arguments: --quick``, naming neither the command that refused it nor what was
meant. :class:`ArgumentParser` names the sub-command that was given it, the closest option it has (``--robot-sped``:
did you mean ``--robot-speed``?) and the sibling commands that have the option itself (``--quick``: an option of
``foresight eval all``). Sub-parsers made with ``add_subparsers`` are of the same class.
"""

from __future__ import annotations

import argparse
import difflib
from collections.abc import Sequence
from typing import Any

__all__ = ["ArgumentParser"]


class ArgumentParser(argparse.ArgumentParser):
    """``argparse.ArgumentParser`` whose unrecognized arguments are refused by the sub-command given them."""

    def parse_args(self, args: Sequence[str] | None = None,  # type: ignore[override]
                   namespace: argparse.Namespace | None = None) -> argparse.Namespace:
        """As argparse's; an unrecognized argument is an error of the deepest sub-command chosen, with hints."""
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            chosen, siblings = self.chosen(ns)
            chosen.error(chosen.unrecognized(extras, siblings))
        return ns

    def chosen(self, ns: argparse.Namespace) -> tuple[ArgumentParser, dict[str, ArgumentParser]]:
        """The deepest sub-command ``ns`` chose (this parser if none) and its siblings by name."""
        for action in self._actions:
            parsers = getattr(action, "choices", None)
            if action.option_strings or not isinstance(parsers, dict):
                continue
            child = parsers.get(getattr(ns, action.dest, None))
            if isinstance(child, ArgumentParser):
                deeper, siblings = child.chosen(ns)
                if deeper is child:
                    siblings = {name: p for name, p in parsers.items()
                                if p is not child and isinstance(p, ArgumentParser)}
                return deeper, siblings
        return self, {}

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
            close = difflib.get_close_matches(name, mine, n=1, cutoff=0.6)
            if close:
                hints.append(f"did you mean {close[0]}?")
                continue
            owners = [p.prog for p in (siblings or {}).values() if name in p.option_names()]
            if owners:
                hints.append(f"{name} is an option of {', '.join(owners)}")
        text = f"unrecognized arguments: {' '.join(extras)}"
        return text + (f" ({'; '.join(hints)})" if hints else f" (see {self.prog} --help)")
