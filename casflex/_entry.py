"""The ``casflex`` command's entry point: nothing heavy is imported before Ctrl-C is caught, so an
interrupt while CasADi, numpy and matplotlib load exits with 130 and one line, as any other."""

import sys


def main() -> int:
    try:
        from casflex.cli import main as cli_main

        return cli_main()
    except KeyboardInterrupt:  # before the command's own handler exists (it catches every later one)
        sys.stderr.write("\ncasflex: interrupted; nothing was written\n")
        return 130
