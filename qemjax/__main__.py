"""``python -m qemjax`` and the ``qemjax`` command: `qemjax._cli.main`, imported inside the Ctrl-C guard, so an
interrupt while the package is still importing is one line and exit code 130 as well."""
import sys


def main(argv=None) -> int:
    try:
        from ._cli import main as run

        return run(argv)
    except KeyboardInterrupt:
        print("qemjax: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
