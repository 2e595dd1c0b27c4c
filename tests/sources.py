"""Helpers of the tests that read sdrpeer's own source with `ast` (vocabulary, event kinds)."""

from __future__ import annotations

import ast


def docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (of modules, classes, functions and
    attributes: a bare string statement)."""
    return {
        id(node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Expr)
        and isinstance(node.value, ast.Constant)
        and isinstance(node.value.value, str)
    }
