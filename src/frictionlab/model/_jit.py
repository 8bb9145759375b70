"""The one numba decorator of the package's compiled kernels.

``@jit`` compiles in nopython mode with numba's on-disk cache (its directory
is set by :mod:`frictionlab.model._numba_cache`, imported here just before numba)
and numpy's error model: a division by zero gives inf/nan as in numpy
instead of raising, so no divisor is tested for zero on the hot path (the
kernels guard their divisors themselves, and a non-finite state ends a run
as ``fell``).  Measured on the 30 s simulator benchmark: 5-15 % faster,
results identical.

numba itself (about 0.3 s to import) is imported on a kernel's first use,
not when a module defining kernels is imported: ``frictionlab --help``,
``keys`` and ``design`` never run a kernel and never load numba.  A kernel
is a :class:`Kernel` that creates its numba dispatcher on first call (or
when another kernel being compiled refers to it: numba asks the object for
its type through ``_numba_type_``), so compiled callers call the dispatcher
directly, exactly as if it had been decorated with ``numba.njit``.
"""

from __future__ import annotations

import functools
from importlib import import_module
from typing import Any

__all__ = ["Kernel", "jit", "jit_inline", "jit_nogil", "keep_alive"]


@functools.cache
def _njit(nogil: bool = False, inline: bool = False):
    import_module("._numba_cache", __package__)  # sets NUMBA_CACHE_DIR before numba loads
    from numba import njit

    if nogil:
        # a batch driver (frictionlab.studies.batch): the GIL released while it runs,
        # so that several Python threads run batches on the cores at once
        return njit(cache=True, error_model="numpy", nogil=True)
    if inline:
        # inlined into each compiled caller at numba's IR level (a dispatch on a
        # constant kind then costs nothing on the hot path)
        return njit(cache=True, error_model="numpy", inline="always")
    return njit(cache=True, error_model="numpy")


class Kernel:
    """A function compiled by numba on first use (see the module docstring).

    Attributes
    ----------
    py_func : callable
        The Python function (as numba's dispatchers call it).
    """

    def __init__(self, fn, nogil: bool = False, inline: bool = False):
        self.py_func = fn
        self._nogil = nogil
        self._inline = inline
        self._dispatcher = None
        functools.update_wrapper(self, fn)

    @property
    def dispatcher(self):
        """The numba dispatcher (created, and numba imported, on first access)."""
        if self._dispatcher is None:
            self._dispatcher = _njit(self._nogil, self._inline)(self.py_func)
        return self._dispatcher

    def __call__(self, *args: Any) -> Any:
        d = self._dispatcher
        return (d if d is not None else self.dispatcher)(*args)

    @property
    def _numba_type_(self):
        # numba types a global of a function being compiled by this attribute:
        # a compiled caller then calls the dispatcher itself
        return self.dispatcher._numba_type_

    def __getattr__(self, name: str) -> Any:
        # the dispatcher's API (signatures, inspect_types, ...); only reached for
        # names the Kernel does not have itself
        if name.startswith("__"):
            raise AttributeError(name)
        return getattr(self.dispatcher, name)

    def __repr__(self) -> str:
        return f"<frictionlab kernel {self.py_func.__module__}.{self.py_func.__qualname__}>"


def jit(fn) -> Kernel:
    """Decorate a kernel: nopython, cached, numpy error model; compiled on first use."""
    return Kernel(fn)


def jit_inline(fn) -> Kernel:
    """As :func:`jit`, with numba's ``inline="always"``: compiled into each
    compiled caller (for small dispatchers on the hot path).  LLVM does not
    inline a large kernel such as a step of the closed loop, and calling one
    costs its arguments (an array is seven words) every tick;
    ``jit_inline(step.py_func)`` is the same law as a second kernel that a hot
    loop calls instead of ``step``."""
    return Kernel(fn, inline=True)


def jit_nogil(fn) -> Kernel:
    """As :func:`jit`, with numba's ``nogil=True``: the GIL is released while the
    kernel runs (a batch driver, run by several Python threads at once)."""
    return Kernel(fn, nogil=True)


def _keep_alive(a):
    """Nothing: a use of ``a`` in compiled code.  Numba frees an array after
    its last use, and a record taken from it (``a[0]``, ``x.view(dtype)[0]``)
    does not hold it: a kernel that works on such a record calls
    ``keep_alive(a)`` after the record's last use."""
    return None


#: :func:`_keep_alive` compiled; a call, not inlined by numba (whose dead-code
#: elimination would drop an inlined use), so the array lives until it returns.
keep_alive = jit(_keep_alive)
