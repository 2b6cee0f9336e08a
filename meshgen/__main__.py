from meshgen.cli import main

__all__ = []

main()
