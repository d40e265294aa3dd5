"""The project's numba decorator: ``numba.njit`` without the C-callback wrapper.

For every function it compiles, numba also builds a C-callable wrapper, which is only used
when the function is a C callback (``cfunc``) or a first-class function value. No pipeline
function is either, and the wrappers are about a tenth of the LLVM a cold tc_ukf compile
optimizes, so ``njit`` here passes ``no_cfunc_wrapper=True`` (a public ``njit`` option) and is
otherwise ``numba.njit``: the same arguments, an explicit signature compiled eagerly as numba
does. ``tests/pipeline/test_numba_config.py`` checks that every compiled pipeline function is
built this way.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, TypeVar

import numba as nb

if TYPE_CHECKING:
    from numba.core.dispatcher import Dispatcher

_F = TypeVar("_F", bound=Callable[..., object])


def njit(*signature: Any, **options: Any) -> Callable[[_F], Dispatcher[_F]]:
    """``numba.njit(*signature, **options)`` with ``no_cfunc_wrapper=True``, as a decorator."""
    jit: Callable[[_F], Dispatcher[_F]] = nb.njit(  # type: ignore[call-overload]
        *signature, no_cfunc_wrapper=True, **options
    )
    return jit
