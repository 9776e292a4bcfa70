"""Loading numba kernels from numba's on-disk cache without initialising all of numba.

numba loads a cached kernel (``Cache.load_overload``) only after refreshing its CPU target
context: that imports every one of numba's implementation modules and installs their
registries (``numba.np.arraymath`` imports ``scipy.linalg`` with it, to check for BLAS),
0.25–0.35 s of CPU the first time in a process (issue 39: most of an observer's
``make_observer``).  Linking cached machine code uses none of it: it needs numba's runtime
(NRT, which compiled code calls) and the code generator, nothing else.

:func:`load_signature` calls a kernel once (so that its signature is loaded, or compiled)
with the first refresh of that call reduced to initialising the runtime; every later
refresh of the call is numba's own, so a cache miss compiles as before (numba's compiler
refreshes the context itself).  Any compilation later in the process refreshes as usual.
The global compiler lock is held meanwhile: no other thread compiles while the context's
``refresh`` is replaced.  The machine code is the same either way (bit-identical outputs,
tested).  If numba's internals are not as expected, the kernel is called as it is.
"""

from __future__ import annotations

from typing import Any

__all__ = ["load_signature"]


def load_signature(kernel: Any, *args: Any) -> Any:
    """Call the numba dispatcher ``kernel`` on ``args`` (loading that signature from numba's
    cache, or compiling it) with numba's target context initialised only as far as the cached
    code needs (module docstring); returns what the call returns."""
    try:
        from numba.core.compiler_lock import global_compiler_lock
        from numba.core.registry import cpu_target
        from numba.core.runtime import rtsys
    except ImportError:  # (numba's internals moved: the ordinary call)
        return kernel(*args)
    context = cpu_target.target_context
    full_refresh = type(context).refresh
    first = [True]

    def refresh() -> None:
        if first[0]:  # Cache.load_overload's: the runtime only
            first[0] = False
            rtsys.initialize(context)
        else:  # a compilation's (a cache miss)
            full_refresh(context)

    with global_compiler_lock:
        if "refresh" in vars(context):  # (replaced already: not by this function)
            return kernel(*args)
        context.refresh = refresh
        try:
            return kernel(*args)
        finally:
            del context.refresh
