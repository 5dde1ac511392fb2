"""How the integration driver and the models' physics are compiled, and how numba's disk cache stays fresh.

Every compiled function of :mod:`rimd_sim.model.kernel` and its modules is made by a decorator of this module.
With the environment variable ``RIMD_NO_JIT=1`` the decorators return the functions unchanged, so the very same
source runs as plain Python (slow, for debugging and for the test that both paths agree).

numba caches a compiled function on disk (``cache=True``) and checks the entry against the source file of that
function only. A function of one module that compiles in another module's constants or functions would be served
stale after an edit of the other module. The kernel's compiled functions therefore carry the digest of all the
kernel's sources (:data:`KERNEL_MODULES`) in their cache names (:func:`kernel_jit`), and the functions built per
model reach one another through namespaces named after that digest (:func:`namespace`,
:func:`rimd_sim.model.kernel.build_driver`): an edit anywhere in the kernel recompiles all of it.
"""

from __future__ import annotations

import hashlib
import os
import sys
import types
from collections.abc import Iterable
from typing import Any

#: The modules of ``rimd_sim.model`` that make up the integration driver. Their sources form the digest in the
#: cache names of the kernel's compiled functions (:data:`KERNEL_KEY`) and in the name of every driver's namespace.
KERNEL_MODULES = ("kernel", "jit", "layout", "numerics", "contact", "motor", "integration", "events", "records",
                  "sampling")

if os.environ.get("RIMD_NO_JIT") == "1":  # pragma: no cover - exercised by a subprocess test

    def _jit(func):
        return func

    _jit_alloc = _jit
    _jit_fused = _jit
    _jit_inline = _jit
    physics_jit = _jit
    physics_inline = _jit
    JIT = False

    def to_tuple(array, length):
        """The first ``length`` entries of ``array`` as a tuple."""
        return tuple(array[:length])

    def tuple_set(tup, index, value):
        """``tup`` with entry ``index`` replaced by ``value``."""
        return tup[:index] + (value,) + tup[index + 1:]
else:
    from numba import njit

    # The compiled tuple helpers of the Runge-Kutta stages (rimd_sim.model.integration imports them from here).
    # numba types an @intrinsic by its typing function (with the typing context first), not by its call in
    # jitted code, which is what the pure-Python versions above give.
    from numba.cpython.unsafe.tuple import tuple_setitem as tuple_set  # type: ignore[assignment]  # noqa: F401
    from numba.np.unsafe.ndarray import to_fixed_tuple as to_tuple  # type: ignore[assignment]  # noqa: F401

    # Compiled functions *borrow* their arrays: numba's reference counting (NRT) is off in them (``_nrt=False``).
    # With it, every call of a compiled function increments and decrements the count of each array it is given,
    # with atomic instructions, on entry and on exit; the driver's steps pass six arrays to each of their calls,
    # the ensemble's cycles more, and those counts dominate a map's time (docs/benchmarks.md). A borrowing
    # function cannot create an array (numba refuses to compile one that does) and must not return one; the few
    # that allocate their workspace are compiled with ``_jit_alloc``, which keeps the counting, set explicitly: a
    # function left at numba's default inherits its caller's setting. ``_nrt`` is numba's own (underscored)
    # option; tests/model/test_driver.py checks that every compiled function has the one meant.
    def _jit(func):
        return njit(cache=True, fastmath=False, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_alloc(func):
        """A compiled function that creates arrays (its workspace, its results): with reference counting."""
        return njit(cache=True, fastmath=False, nogil=True, _nrt=True)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_fused(func):
        """The Runge-Kutta step: borrowing, with ``a * b + c`` fused into one rounding (FMA, LLVM's ``contract``).

        Only the step, a function of its own that every path calls: a physics function inlined into several
        callers would be fused in one and not in another, and a trajectory would then depend on where a run is
        cut (tests/instruments/test_streaming.py fails so). The fused step's last bits depend on the CPU having FMA
        (x86-64 processors with FMA3, every ARM64): bit-identical runs are bit-identical on one kind of machine.
        """
        return njit(cache=True, fastmath={"contract"}, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def _jit_inline(func):
        """A small function of the hot loop, inlined into its callers at numba's IR level: no call per use.

        It takes its callers' compilation options (reference counting, FMA contraction).
        """
        return njit(cache=True, fastmath=False, nogil=True, inline="always")(func)

    def physics_jit(func):
        """A model's physics function, not cached on its own.

        It is compiled into the driver built from it, whose cache entry is keyed by the physics sources
        (:func:`rimd_sim.model.kernel.build_driver`), so an edit to the physics is never served stale.
        """
        return njit(cache=False, fastmath=False, nogil=True, _nrt=False)(func)  # type: ignore[call-overload]  # _nrt: numba's option

    def physics_inline(func):
        """A small physics function of the hot loop, inlined into the driver (see :func:`physics_jit`)."""
        return njit(cache=False, fastmath=False, nogil=True, inline="always")(func)

    JIT = True


def _files_key(paths: Iterable[str]) -> str:
    digest = hashlib.sha256()
    for path in paths:
        with open(path, "rb") as f:
            digest.update(f.read())
    return digest.hexdigest()[:12]


def source_key(*modules) -> str:
    """A digest of the source files of ``modules``: part of the compiled driver's cache key."""
    return _files_key(module.__file__ for module in modules)


#: Digest of the sources of :data:`KERNEL_MODULES`, in that order.
KERNEL_KEY = _files_key(os.path.join(os.path.dirname(__file__), f"{name}.py") for name in KERNEL_MODULES)


def jit_for(scope: str, *, allocates: bool = False, fused: bool = False, inline: bool = False):
    """A decorator that compiles functions (``_jit``) under the qualified name ``scope.fn``.

    ``allocates``: the functions create arrays (``_jit_alloc``, with numba's reference counting); by default they
    borrow the arrays they are given (``_jit``). ``fused``: the Runge-Kutta step's (``_jit_fused``). ``inline``:
    inlined into their callers (``_jit_inline``).

    numba names the compiled symbols and the cache files after a function's qualified name. The functions a
    factory builds for one model share their Python qualified name, and two models' functions loaded from the
    cache into one process must not share a symbol (the second would call the first's code): their ``scope``
    holds the model's name. The kernel's module-level functions have a ``scope`` that holds :data:`KERNEL_KEY`
    (:func:`kernel_jit`).
    """
    jit = _jit_alloc if allocates else _jit_fused if fused else _jit_inline if inline else _jit

    def compiled(func):
        func.__qualname__ = f"{scope}.{func.__name__}"
        return jit(func)

    return compiled


def kernel_jit(*, inline: bool = False):
    """The decorator of a module-level compiled function of the kernel: cached under the kernel's digest.

    The function may compile in the constants and functions of any module of :data:`KERNEL_MODULES`; its cache
    name changes with any of their sources, so an edit of one is never served stale through another.
    """
    return jit_for(f"kernel_{KERNEL_KEY}", inline=inline)


def load_cached(dispatcher) -> int:
    """Load every specialisation of ``dispatcher`` that numba's disk cache holds for this process; return the count.

    The fused step must be in the process before anything that calls it. numba links a callee's code into each
    caller (a weak, ``linkonce_odr`` copy, which LLVM optimises again in the caller's module), and the process runs
    the first copy it loads. Compiling a caller compiles the callee first, so a process that compiles runs the
    callee's own code; a process that loaded only the caller from the cache would run the caller's copy. With FMA
    contraction the two copies can round differently (they fuse different pairs), so a cold process and a warm one
    would give trajectories that differ in their last bits. Loaded first, the callee's own code is the one every
    caller runs, cold or warm. An empty cache loads nothing, and the first call compiles in that order anyway.
    """
    cache = getattr(dispatcher, "_cache", None)
    index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
    if cache is None or index is None:   # RIMD_NO_JIT, or a numba whose cache is laid out otherwise
        return 0
    codegen = dispatcher.targetctx.codegen()
    loaded = 0
    for key in index():
        signature = key[0]
        if key == cache._index_key(signature, codegen) and signature not in dispatcher.overloads:
            dispatcher.compile(signature)
            loaded += 1
    return loaded


def namespace(name: str, doc: str) -> Any:
    """A module registered in ``sys.modules`` (so numba's cache key pickles it by its name).

    Typed ``Any``: its attributes (the compiled functions, ...) are set after it is made.
    """
    ns = types.ModuleType(name, doc)
    sys.modules[name] = ns
    return ns
