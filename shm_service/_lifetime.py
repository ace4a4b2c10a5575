"""A child process that ends with its parent: the Linux kernel's parent-death signal.

A leaf module (it imports nothing of the project), so that the kernels' compile step
(``warmup``) and the service's processes can both ask for it.
"""

from __future__ import annotations

import sys

__all__ = ["set_parent_death_signal"]

_PR_SET_PDEATHSIG = 1


def set_parent_death_signal(signum: int) -> bool:
    """Ask the Linux kernel for ``signum`` when the parent (thread) ends; False where unsupported."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        return int(libc.prctl(_PR_SET_PDEATHSIG, int(signum), 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False
