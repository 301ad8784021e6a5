"""The C reference firmware (C99 sources, Makefile) and its Python-side helpers.

Modules: `extractor` (ctypes binding to the C feature extractor `extract.c`, built by the Makefile's
`lib` target, for the accuracy tests and the benchmark).
"""
