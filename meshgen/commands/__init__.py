"""One module per CLI command; each parses and prints, the work lives in importable functions."""

__all__ = []
