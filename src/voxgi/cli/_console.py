"""What the command line prints: progress lines, diagnostics and warnings."""

from __future__ import annotations

import sys

from ._args import EXIT_INTERRUPTED


def _say(text: str) -> None:
    """Print one line of progress on stdout at once."""
    print(text, flush=True)


def _note(args, text: str) -> None:
    """Print an indented diagnostic line, only with ``--verbose``."""
    if args.verbose:
        _say(f"  {text}")


def _interrupted(text: str) -> int:
    """Report an interrupted render on stderr; returns its exit code."""
    print(f"voxgi render: {text}", file=sys.stderr, flush=True)
    return EXIT_INTERRUPTED


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Print a warning as ``warning: <message>`` on stderr: a command-line user
    needs what it says, not the source line that raised it."""
    print(f"warning: {message}", file=sys.stderr if file is None else file, flush=True)
