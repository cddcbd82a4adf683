"""Taichi's Python front end, made cheaper where this package pins Taichi (1.7.4).

Taichi turns every kernel into IR from its Python source in each process, also when the
kernel then comes from its offline cache (the cache's key is that IR): for a cached start of
a small scene that front end is about half the time to the first step. Two of its costs
repeat work whose answer cannot change within a process, and ``backend.init`` removes them
before Taichi starts: the text of each source position, wrapped at 80 columns for every
statement and expression (``use_fast_positions``), and the source of each function, read
again at every call site it is inlined into (``use_cached_sources``). Reading the sources
once builds the same IR (``tests/test_backend.py`` holds it by the offline cache's keys);
the unwrapped positions change only the text of Taichi's errors, which still name the file,
line and column (the same test file). On another Taichi both leave it as it is.
"""

from __future__ import annotations

import textwrap

# The Taichi whose front end these patches know: on any other they leave it as it is.
PINNED_TAICHI = (1, 7, 4)


def _pinned() -> bool:
    import taichi as ti

    return tuple(ti.__version__) == PINNED_TAICHI


def source_position(ctx, node) -> str:
    """Where ``node`` of a kernel's source is, as Taichi's errors show it: "File ..., line
    N, in f:", the line, and a caret under the node (from its column to the line's end when
    it spans lines).

    Taichi builds this text for every statement and expression of every kernel it turns into
    IR, also when the kernel comes from its offline cache (the cache key is that IR), and
    wraps each line at 80 columns with ``textwrap``: measured on 2 cores, a third of a cached
    start of ``two_squares`` (2.7-2.9 s to its first steps, 1.8-2.0 s without the wrapping;
    the pillar compiled anew, tests' setting, 5.3-6.3 s and 4.4-5.7 s). This is the same
    text without the wrapping and the lines after a node's first (``use_fast_positions``).
    """
    lineno = node.lineno + ctx.lineno_offset
    code = ctx.src[node.lineno - 1]
    start = ctx.indent + node.col_offset
    if node.end_lineno == node.lineno:
        end = ctx.indent + node.end_col_offset
    else:
        end = len(code.rstrip())
    hint = " " * start + "^" * max(end - start, 1)
    return f'File "{ctx.file}", line {lineno}, in {ctx.func.func.__name__}:\n{code}\n{hint}\n'


def use_fast_positions() -> bool:
    """Let Taichi describe a kernel's source positions with ``source_position`` (no
    ``textwrap``); True when in effect. Only on the Taichi this package pins (1.7.4), whose
    ``ASTTransformerContext.get_pos_info`` it replaces; elsewhere Taichi is left as is."""
    try:
        from taichi.lang.ast import ast_transformer_utils as utils
    except ImportError:
        return False
    context = getattr(utils, "ASTTransformerContext", None)
    if not _pinned() or not hasattr(context, "get_pos_info"):
        return False
    context.get_pos_info = source_position
    return True


def use_cached_sources() -> bool:
    """Let Taichi read each kernel's and function's source once a process, not at every
    call site it inlines (True when in effect; only on the Taichi this package pins, 1.7.4,
    whose ``kernel_impl`` reads sources in ``_get_tree_and_ctx`` alone; elsewhere Taichi is
    left as is).

    Taichi turns a kernel into IR from its Python source in every process, also when the
    kernel then comes from its offline cache (the cache key is that IR), and for each
    ``ti.func`` it inlines it reads the function's source again: ``inspect.getsourcelines``
    (which tokenises the function's block each time) and ``textwrap.fill`` of each line.
    The engine's stepping kernel inlines about 860 functions, so the same few dozen were
    read hundreds of times. Here ``kernel_impl``'s ``getsourcefile``, ``getsourcelines``
    and ``textwrap`` keep what they returned, by code object (closures made again share
    theirs) and by line; the tree is still parsed anew at each call (Taichi's transformer
    writes into it). So the IR, and with it the cache key and every bit a run computes, is
    what it was (``tests/test_backend.py``). A source file edited while a process runs is
    not read again by it: a kernel compiled later sees the source as first read, as a
    Python function's code does."""
    try:
        from taichi.lang import kernel_impl
    except ImportError:
        return False
    names = ("getsourcefile", "getsourcelines", "textwrap")
    if not _pinned() or not all(hasattr(kernel_impl, n) for n in names):
        return False
    if isinstance(kernel_impl.textwrap, _KeptTextwrap):
        return True
    kernel_impl.getsourcefile = _kept_by_code(kernel_impl.getsourcefile)
    kernel_impl.getsourcelines = _kept_by_code(kernel_impl.getsourcelines, copy=True)
    kernel_impl.textwrap = _KeptTextwrap()
    return True


def _kept_by_code(read, copy: bool = False):
    """``read(func)``, kept by ``func``'s code object (``use_cached_sources``); with
    ``copy``, a ``(lines, start)`` answer is handed out as a new list each time."""
    kept: dict = {}

    def kept_read(func):
        code = getattr(func, "__code__", None)
        if code is None:
            return read(func)
        if code not in kept:
            kept[code] = read(func)
        found = kept[code]
        return (list(found[0]), found[1]) if copy else found

    return kept_read


class _KeptTextwrap:
    """``textwrap`` as Taichi's ``kernel_impl`` uses it, each line's ``fill`` kept
    (``use_cached_sources``)."""

    dedent = staticmethod(textwrap.dedent)

    def __init__(self):
        self._filled: dict = {}

    def fill(self, text, **options):
        key = (text, tuple(sorted(options.items())))
        if key not in self._filled:
            self._filled[key] = textwrap.fill(text, **options)
        return self._filled[key]
