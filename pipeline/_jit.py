"""The project's numba decorator: ``numba.njit`` without the C-callback wrapper, and with an
explicit signature compiled at first use instead of at import.

For every function it compiles, numba also builds a C-callable wrapper, which is only used
when the function is a C callback (``cfunc``) or a first-class function value. No pipeline
function is either, and the wrappers are about a tenth of the LLVM a cold tc_ukf compile
optimizes, so ``njit`` here passes ``no_cfunc_wrapper=True`` and is otherwise ``numba.njit``
(the same arguments; the function stays callable from Python and from compiled code).
``tests/pipeline/test_numba_config.py`` checks that every compiled pipeline function is built
this way.

**Pinned signatures.** ``numba.njit(signature)`` compiles the signature when the module is
imported and then allows no other, so a call from compiled code converts its arguments
(literal integers, arrays of another layout) instead of compiling a new specialization. Here
the signature is *pinned* instead: nothing is compiled at import; the first use (a call from
Python, a call typed inside a function being compiled, or ``dispatcher.compile``) compiles
the one signature, and no other is ever compiled. A cold run thus compiles these helpers
inside the kernel's compile, where the cold-compile helper (``estimation.compile_helper``)
can compile them on the other core, instead of before it in every process that imports them.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import numba as nb

if TYPE_CHECKING:
    from numba.core.dispatcher import Dispatcher

_F = TypeVar("_F", bound=Callable[..., object])


def njit(signature: Any = None, /, **options: Any) -> Callable[[_F], Dispatcher[_F]]:
    """``numba.njit(**options)`` with ``no_cfunc_wrapper=True``, as a decorator; with
    ``signature``, the function compiles that signature at first use and no other."""

    def decorate(fn: _F) -> Dispatcher[_F]:
        jit = nb.njit(no_cfunc_wrapper=True, **options)  # type: ignore[call-overload]
        compiled: Dispatcher[_F] = jit(fn)
        if signature is not None and hasattr(compiled, "_compile_for_args"):
            _pin(compiled, signature)  # not with NUMBA_DISABLE_JIT: ``fn`` itself is returned
        return compiled

    return decorate


def pinned_signature(dispatcher: Any) -> tuple[Any, ...] | None:
    """The argument types ``dispatcher`` is pinned to, or None if it is not pinned."""
    args: tuple[Any, ...] | None = getattr(dispatcher, "_navreplay_pinned", None)
    return args


def _pin(dispatcher: Any, signature: Any) -> None:
    """Make ``dispatcher`` compile ``signature`` at its first use, and then nothing else.

    numba asks a dispatcher for an overload in three places: ``compile`` (from Python, and
    from ``get_call_template`` when a call is typed in compiled code) and
    ``_compile_for_args`` (a call from Python with no matching overload yet). Each is wrapped
    to compile the pinned signature first and then disable compilation, which is the state
    ``numba.njit(signature)`` leaves a dispatcher in at import.
    """
    from numba.core import sigutils

    args, _ = sigutils.normalize_signature(signature)  # type: ignore[no-untyped-call]
    args = tuple(args)
    compile_ = dispatcher.compile
    compile_for_args = dispatcher._compile_for_args

    def ensure() -> None:
        if dispatcher._can_compile:
            compile_(args)
            dispatcher.disable_compile()

    def compile_pinned(sig: Any) -> Any:
        wanted, _ = sigutils.normalize_signature(sig)  # type: ignore[no-untyped-call]
        if tuple(wanted) != args:
            raise TypeError(
                f"{dispatcher.py_func.__qualname__} is pinned to {args}, not {tuple(wanted)}"
            )
        ensure()
        return dispatcher.overloads[args].entry_point

    def compile_for_args_pinned(*a: Any, **k: Any) -> Any:
        if not dispatcher._can_compile:  # the C dispatcher found no conversion: numba's error
            return compile_for_args(*a, **k)
        ensure()
        return dispatcher  # numba calls this again, now with the pinned overload to match

    def get_call_template(call_args: Any, kws: Any) -> Any:
        ensure()
        return type(dispatcher).get_call_template(dispatcher, call_args, kws)

    dispatcher._navreplay_pinned = args
    dispatcher.compile = compile_pinned
    dispatcher._compile_for_args = compile_for_args_pinned
    dispatcher.get_call_template = get_call_template
