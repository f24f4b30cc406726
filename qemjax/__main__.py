"""``python -m qemjax`` and the ``qemjax`` command: `qemjax._cli.main`, imported inside the Ctrl-C guard, so an
interrupt while the package is still importing is one line and exit code 130 as well; ``--version`` alone
is answered here, before importing it."""
import sys


def main(argv=None) -> int:
    """The command's exit code. Called as the program (``argv`` None: the process's own arguments), it
    ends by freezing the garbage collector's objects (`_cli.exit_soon`)."""
    program = argv is None
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        if argv == ["--version"]:  # without importing the command's modules (numpy, the settings)
            from . import _version_line

            print(_version_line())
            return 0
        from ._cli import exit_soon, leave, main as run

        code = leave(lambda: run(argv))
        if program:
            exit_soon()
        return code
    except KeyboardInterrupt:  # while the package was still importing
        print("qemjax: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
