"""Command line: ``voxgi render SCENE -o out.exr``, ``voxgi compare SCENE`` and ``voxgi scenes``.

Exit codes: 0 done; 1 a scene file or value that cannot be used; 2 a bad
command line or an output that cannot be written (both checked before any
work; missing output folders are created); 130 interrupted (Ctrl-C).
Errors are one line on stderr, never a traceback.
"""

from __future__ import annotations

import sys
import warnings

from ._args import EXIT_INTERRUPTED, EXIT_USAGE, OUTPUT_EXTENSIONS, UsageError, build_parser
from ._console import _show_warning
from ._files import check_writable, output_paths
from .compare import run_compare
from .render import run_render
from .scenes import plain_text, run_scenes

__all__ = [
    "EXIT_INTERRUPTED",
    "EXIT_USAGE",
    "OUTPUT_EXTENSIONS",
    "UsageError",
    "build_parser",
    "check_writable",
    "main",
    "output_paths",
    "plain_text",
    "run_compare",
    "run_render",
    "run_scenes",
]


def main(argv: list[str] | None = None) -> int:
    """Run the command line; returns the exit code, or raises ``SystemExit``
    on an error (code 2 for the command line and outputs, as argparse does,
    else the one-line message, which exits with 1)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    run = {"render": run_render, "compare": run_compare, "scenes": run_scenes}[args.command]
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return run(args)
    except UsageError as exc:
        print(f"voxgi {args.command}: error: {exc}", file=sys.stderr)
        raise SystemExit(EXIT_USAGE) from None
    except (ValueError, TypeError, OSError) as exc:
        # bad or unreadable scene files and values: a message, not a traceback
        raise SystemExit(f"voxgi {args.command}: error: {exc}") from None
    except MemoryError:
        raise SystemExit(
            f"voxgi {args.command}: error: out of memory (a lower --resolution or a smaller "
            "image needs less)"
        ) from None
    except RecursionError:
        raise SystemExit(f"voxgi {args.command}: error: input nested too deeply") from None
    except KeyboardInterrupt:
        print(f"voxgi {args.command}: interrupted; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
