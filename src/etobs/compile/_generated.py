"""Module name under which etobs compiles the wrappers of user functions (empty on purpose).

numba records the module of a compiled function's globals and imports it again when it
loads the function's cached machine code; the wrappers of :mod:`etobs.compile.functions`
name this module.
"""
