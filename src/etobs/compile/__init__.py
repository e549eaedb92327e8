"""Compiling the user's one-run functions for the engine.

Users write every model function once, for one run, on 1-D arrays, in numpy or
``math`` (:mod:`etobs.compile.functions`). etobs compiles each one with numba into a
small C-callable function and caches its machine code on disk under a hash of its
content (:mod:`etobs.compile.fingerprint`, :mod:`etobs.compile.cache`), so the engine,
compiled once per machine, calls it by address (:mod:`etobs.compile.ccall`).
"""

from etobs.compile.functions import CompiledFunction, FunctionSpec, compile_function

__all__ = ["CompiledFunction", "FunctionSpec", "compile_function"]
