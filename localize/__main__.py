"""``python -m localize ...`` and the ``localize`` command: the command line of :mod:`localize.cli`.

The command line's libraries (matplotlib, scipy, ...) load here, inside a guard: a Ctrl-C while they load
says so in one line instead of a traceback.
"""

import sys


def main() -> int:
    """Load :mod:`localize.cli` and run its ``main`` (exit status 130 for a Ctrl-C while loading)."""
    try:
        from .cli import main as cli_main
    except KeyboardInterrupt:  # nothing has been read or written yet
        print("localize: interrupted; nothing written", file=sys.stderr)
        return 130
    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
