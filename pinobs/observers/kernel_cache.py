"""Loading numba kernels from numba's on-disk cache without initialising all of numba.

numba loads a cached kernel (``Cache.load_overload``) only after refreshing its CPU target
context: that imports every one of numba's implementation modules and installs their
registries (``numba.np.arraymath`` imports ``scipy.linalg`` with it, to check for BLAS),
0.25–0.35 s of CPU the first time in a process (issue 39: most of an observer's
``make_observer``).  Linking cached machine code uses none of it: it needs numba's runtime
(NRT, which compiled code calls), the code generator and the numba modules named by the
kernels' pickled environments (numba imports those as it unpickles them).

:func:`load_signature` loads a kernel's signature (the arguments' types, as numba's call
types them) by the dispatcher's ``compile(signature)``, with that kernel's
``Cache.load_overload`` replaced, for the load, by the same steps less the refresh: numba's
runtime initialised, then the cached code loaded; then calls the kernel once.  Its own call
(``_compile_for_args``) would first initialise numba's extensions
(``entrypoints.init_all``: it reads the entry points of every installed distribution,
8–15 ms of CPU here with about 200 of them) though a cache hit compiles nothing: a hit
skips it; a miss runs it, then compiles as before (numba's compiler refreshes the context
itself, fully), as does any compilation later in the process.  The machine code is the same
either way (bit-identical outputs, tested).  If numba's internals are not as expected, the
kernel is called as it is.
"""

from __future__ import annotations

from typing import Any

__all__ = ["load_signature"]


def load_signature(kernel: Any, *args: Any) -> Any:
    """Call the numba dispatcher ``kernel`` on ``args``, its signature loaded first from
    numba's cache (or compiled) without numba's refresh before the cache load and, on a hit,
    without initialising numba's extensions (module docstring); returns what the call
    returns."""
    try:
        from numba.core.caching import Cache
        from numba.core.runtime import rtsys
    except ImportError:  # (numba's internals moved: the ordinary call)
        return kernel(*args)
    cache = getattr(kernel, "_cache", None)
    needs = ("_load_overload", "_guard_against_spurious_io_errors")
    hooks = ("compile", "typeof_pyval", "_compilation_chain_init_hook")
    if not isinstance(cache, Cache) or not all(hasattr(cache, n) for n in needs):
        return kernel(*args)  # (no disk cache: the ordinary call)
    if not all(hasattr(kernel, n) for n in hooks):
        return kernel(*args)  # (numba's dispatcher differs: the ordinary call)

    def load_overload(sig: Any, target_context: Any) -> Any:
        rtsys.initialize(target_context)  # instead of target_context.refresh()
        with cache._guard_against_spurious_io_errors():
            loaded = cache._load_overload(sig, target_context)
        if loaded is None:  # a miss: numba's extensions first, as its own call does
            kernel._compilation_chain_init_hook()
        return loaded

    cache.load_overload = load_overload  # type: ignore[method-assign]  # (this load only)
    try:  # the signature numba's call would type (its typeof_pyval), loaded or compiled
        kernel.compile(tuple(kernel.typeof_pyval(a) for a in args))
    finally:
        del cache.load_overload
    return kernel(*args)  # (the signature's machine code, found by the dispatcher)
