"""The sampled rule as C99 for microcontrollers, from the kinds' descriptors (``etobs codegen c``).

:mod:`etobs.codegen.c_node` writes one node's module, :mod:`etobs.codegen.vectors` the
conformance vectors that check it against the Python sensor node, and
:mod:`etobs.codegen.c_expr` translates the formulas of :mod:`etobs.formulas` into C.
"""
