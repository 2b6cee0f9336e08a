import sys

from meshgen.run.early import start_early

start_early(sys.argv[1:])  # before click, NumPy and the command are imported: meshgen.run.early

from meshgen.cli import main  # noqa: E402

__all__ = []

main()
