"""Batched evaluation over stacked states on sodyn's thread pool, with the GIL released.

``Q`` has shape ``(N, nq)``; ``V``, ``A`` and ``TAU`` shape ``(N, nv)`` (for a model loaded
with ``mimic=True``, its reduced ``nq`` and ``nv``). Results are stacked along a leading axis of
length ``N`` and equal, bit for bit, ``N`` sequential calls.
``threads=None`` uses one thread per core; ``threads=T`` a pool of ``T`` threads (the caller
plus ``T - 1`` helpers), started on first use and kept.
"""

from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np

from . import _sodyn
from ._sodyn import Model

__all__ = [
    "aba",
    "crba",
    "fd_derivatives",
    "fd_so_derivatives",
    "id_derivatives",
    "id_so_derivatives",
    "nonlinear_effects",
    "rnea",
]


def rnea(model: Model, Q: Any, V: Any, A: Any, threads: Optional[int] = None) -> np.ndarray:
    """Inverse dynamics at every state: ``(N, nv)``."""
    return _sodyn.batch_rnea(model, Q, V, A, threads)


def crba(model: Model, Q: Any, threads: Optional[int] = None) -> np.ndarray:
    """Mass matrices: ``(N, nv, nv)``."""
    return _sodyn.batch_crba(model, Q, threads)


def aba(model: Model, Q: Any, V: Any, TAU: Any, threads: Optional[int] = None) -> np.ndarray:
    """Forward dynamics: ``(N, nv)``."""
    return _sodyn.batch_aba(model, Q, V, TAU, threads)


def nonlinear_effects(model: Model, Q: Any, V: Any, threads: Optional[int] = None) -> np.ndarray:
    """Nonlinear effects ``C v + g``: ``(N, nv)``."""
    return _sodyn.batch_nonlinear_effects(model, Q, V, threads)


def id_derivatives(
    model: Model, Q: Any, V: Any, A: Any, threads: Optional[int] = None
) -> Tuple[np.ndarray, np.ndarray]:
    """``(dtau_dq, dtau_dv)``, each ``(N, nv, nv)``."""
    return _sodyn.batch_id_derivatives(model, Q, V, A, threads)


def fd_derivatives(
    model: Model, Q: Any, V: Any, TAU: Any, threads: Optional[int] = None
) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(dqdd_dq, dqdd_dv, Minv)``, each ``(N, nv, nv)``."""
    return _sodyn.batch_fd_derivatives(model, Q, V, TAU, threads)


def id_so_derivatives(
    model: Model, Q: Any, V: Any, A: Any, threads: Optional[int] = None
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(d2tau_dq2, d2tau_dv2, d2tau_dqdv, dM_dq)``, each ``(N, nv, nv, nv)``."""
    return _sodyn.batch_id_so_derivatives(model, Q, V, A, threads)


def fd_so_derivatives(
    model: Model, Q: Any, V: Any, TAU: Any, threads: Optional[int] = None
) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(d2qdd_dq2, d2qdd_dv2, d2qdd_dqdv, d2qdd_dtaudq)``, each ``(N, nv, nv, nv)``."""
    return _sodyn.batch_fd_so_derivatives(model, Q, V, TAU, threads)
