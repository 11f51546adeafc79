"""Sparse LU factorisations of the implicit step's matrices, and factorising in the background.

:func:`nested_dissection` orders a 3×3-block pattern (METIS through ``pymetis``);
:func:`_local_factor` factorises the filtered block of a node set (the local solve of the
Schwarz preconditioner of :mod:`unmesh.fem.solvers`).

:class:`Factorization` is SuperLU of a symmetric matrix in a given DOF order, in double
precision or, symmetrically Jacobi-scaled, in single precision: ``D^{-1/2} A D^{-1/2}``
(unit diagonal) is factorised in float32 and ``A⁻¹ r = D^{-1/2} (D^{-1/2} A D^{-1/2})⁻¹
D^{-1/2} r``. Unscaled, single precision stalled PCG on the bunny-slicing benchmark (lumped
masses spanning 5 decades after slivers); scaled, it is a preconditioner as good as the
double-precision one there (same CG iterations in every step) at half the factor's memory.

:class:`Job` runs a function in a thread (SuperLU's factorisation releases the GIL) or,
``threaded=False``, at once; either way its result is collected by :meth:`Job.result`,
so a caller that collects at a point fixed by its own state gets the same results
whatever the thread timing.

Example
-------
>>> import numpy as np
>>> import scipy.sparse as sp
>>> A = sp.csr_array(np.array([[4.0, 1.0], [1.0, 3.0]]))
>>> lu = Job(Factorization, A, None, single=True).result()
>>> bool(np.allclose(lu.solve(np.array([5.0, 4.0])), [1.0, 1.0], rtol=1e-6))
True
"""

from __future__ import annotations

import ctypes
import functools
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.sparse as sp

from unmesh._threads import background_work
from unmesh.fem import _solve_kernels as SK

__all__ = ["Factorization", "Job", "block_csr", "nested_dissection"]


def nested_dissection(indptr: np.ndarray, indices: np.ndarray, *, fast: bool = True) -> np.ndarray | None:
    """METIS nested-dissection order (n,) of the nodes of a block pattern, or None without ``pymetis``.

    ``fast``: METIS' ``METIS_NodeND`` of ``pymetis``' library called through ctypes, which
    releases the GIL for the call (the same order as ``pymetis.nested_dissection``,
    ``fast=False``, which holds the GIL throughout: 160-200 ms on the bunny benchmark,
    in which a background refactorisation stopped the main thread). Calls are serialised
    by a lock (the main thread orders local sets while the background thread may order
    the whole mesh).

    Example
    -------
    >>> import numpy as np
    >>> perm = nested_dissection(np.array([0, 2, 4]), np.array([0, 1, 0, 1]))
    >>> perm is None or sorted(perm.tolist()) == [0, 1]
    True
    """
    try:
        import pymetis
    except ImportError:
        return None
    n = len(indptr) - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    off = indices != rows
    xadj = np.r_[0, np.cumsum(np.bincount(rows[off], minlength=n))]
    adjncy = indices[off]
    node_nd = _metis_node_nd() if fast else None
    if node_nd is not None:
        P = ctypes.c_void_p
        nv = np.array([n], np.int64)
        xadj = np.ascontiguousarray(xadj, dtype=np.int64)
        adjncy = np.ascontiguousarray(adjncy, dtype=np.int64)
        perm, iperm = np.empty(n, np.int64), np.empty(n, np.int64)
        with _METIS_LOCK:
            status = node_nd(P(nv.ctypes.data), P(xadj.ctypes.data), P(adjncy.ctypes.data), None, None,
                             P(perm.ctypes.data), P(iperm.ctypes.data))
        if status == 1:  # METIS_OK
            return perm
    xadj, adjncy = xadj.astype(np.int32), adjncy.astype(np.int32)
    if hasattr(pymetis, "CSRAdjacency"):
        perm, _ = pymetis.nested_dissection(adjacency=pymetis.CSRAdjacency(xadj, adjncy))
    else:  # pymetis < 2025
        perm, _ = pymetis.nested_dissection(xadj=xadj, adjncy=adjncy)
    return np.asarray(perm, dtype=np.int64)


_METIS_LOCK = threading.Lock()


@functools.cache
def _metis_node_nd() -> Any:
    """``METIS_NodeND`` of ``pymetis``' extension module through ctypes, or None (looked up once).

    Only with 64-bit ``idx_t`` (pymetis' build), told by ``METIS_SetDefaultOptions``: it sets
    its ``METIS_NOPTIONS`` (40) options to -1, i.e. 40 int64 words, or 20 if ``idx_t`` is 32-bit.
    """
    try:
        from pymetis import _internal

        lib = ctypes.CDLL(_internal.__file__)
        opts = np.zeros(80, np.int64)
        lib.METIS_SetDefaultOptions(ctypes.c_void_p(opts.ctypes.data))
        if np.all(opts[:40] == -1) and np.all(opts[40:] == 0):
            fn = lib.METIS_NodeND
            fn.restype = ctypes.c_int
            return fn
    except (ImportError, OSError, AttributeError):
        pass
    return None


class Factorization:
    """SuperLU of the symmetric (m, m) matrix ``A`` in the order ``perm`` (None: SuperLU's minimum degree).

    ``single``: factorise ``D^{-1/2} A D^{-1/2}`` (D the diagonal of A, positive) in float32
    (module docstring); :meth:`solve` still takes and returns float64.

    Example
    -------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> lu = Factorization(sp.csr_array(np.diag([2.0, 4.0])), np.array([1, 0]))
    >>> lu.solve(np.array([1.0, 1.0])).tolist()
    [0.5, 0.25]
    """

    def __init__(self, A: sp.sparray, perm: np.ndarray | None, *, single: bool = False) -> None:
        A = sp.csr_array(A)
        self.scale: np.ndarray | None = None
        if single:
            d = A.diagonal()
            if not np.all(d > 0):
                raise RuntimeError("single precision needs a positive diagonal")
            self.scale = 1.0 / np.sqrt(d)
            vals = A.data * np.repeat(self.scale, np.diff(A.indptr)) * self.scale[A.indices]
            A = sp.csr_array((vals.astype(np.float32), A.indices, A.indptr), shape=A.shape)
        self.perm = perm
        self.iperm: np.ndarray | None = None
        if perm is None:
            self.lu = _splu(sp.csc_array(A), "MMD_AT_PLUS_A")
        else:
            self.iperm = np.empty_like(perm)
            self.iperm[perm] = np.arange(len(perm))
            self.lu = _splu(sp.csc_array(A[perm][:, perm]), "NATURAL")

    @classmethod
    def from_blocks(cls, indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, node_perm: np.ndarray, *,
                    single: bool = False) -> Factorization:
        """The factorisation of a symmetric 3×3-block CSR matrix (blocks (nnz, 9)) in the node order ``node_perm``.

        The same as ``Factorization(block_csr(...), dof order of node_perm, single=single)`` (up to
        the round-off of A's asymmetry), with the permuted (and scaled) matrix built by a
        kernel that releases the GIL (:func:`unmesh.fem._solve_kernels.permuted_scalar_csr`):
        scipy's conversions and indexing took the GIL often enough to slow the main thread
        and themselves when run beside it (the background factorisation).
        """
        self = cls.__new__(cls)  # the attributes of __init__, set below
        data = np.empty(9 * len(indices), np.float32 if single else np.float64)
        node_perm = np.ascontiguousarray(node_perm, dtype=np.int64)
        ptr, idx, scale = SK.permuted_scalar_csr(np.ascontiguousarray(indptr, dtype=np.int64),
                                                 np.ascontiguousarray(indices, dtype=np.int64),
                                                 np.ascontiguousarray(blocks, dtype=np.float64), node_perm, single, data)
        if single and not np.all(np.isfinite(scale)):
            raise RuntimeError("single precision needs a positive diagonal")
        self.scale = scale if single else None
        self.perm = (3 * node_perm[:, None] + np.arange(3)).ravel()
        self.iperm = np.empty_like(self.perm)
        self.iperm[self.perm] = np.arange(len(self.perm))
        n3 = len(ptr) - 1
        self.lu = _splu(sp.csc_array((data, idx, ptr), shape=(n3, n3)), "NATURAL")
        return self

    @property
    def nnz(self) -> int:
        """Non-zeros of the factors L and U."""
        return int(self.lu.L.nnz + self.lu.U.nnz)

    def solve(self, r: np.ndarray) -> np.ndarray:
        """``A⁻¹ r`` for r (m,) float64."""
        if self.scale is not None:
            r = (r * self.scale).astype(np.float32)
        if self.perm is not None:
            r = r[self.perm]
        y = self.lu.solve(r)
        if self.iperm is not None:
            y = y[self.iperm]
        if self.scale is not None:
            y = y * self.scale
        return y


def _splu(A: sp.csc_array, order: str) -> Any:
    from scipy.sparse.linalg import splu

    return splu(A, permc_spec=order, options={"SymmetricMode": True})


class Job:
    """``fn(*args, **kwargs)`` run in a daemon thread (``threaded=False``: now, in the caller's).

    Example
    -------
    >>> Job(sum, [1, 2, 3]).result(), Job(sum, [1, 2], threaded=False).result()
    (6, 3)
    """

    def __init__(self, fn: Callable[..., Any], *args: Any, threaded: bool = True, **kwargs: Any) -> None:
        self._value: Any = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None
        if threaded:
            self._thread = threading.Thread(target=self._run_background, args=(fn, args, kwargs), daemon=True,
                                            name="unmesh-factorization")
            self._thread.start()
        else:
            self._run(fn, args, kwargs)

    def _run(self, fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
        try:
            self._value = fn(*args, **kwargs)
        except BaseException as exc:  # re-raised in the collecting thread
            self._error = exc

    def _run_background(self, fn: Callable[..., Any], args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
        # the main thread's numba kernels leave this thread its core (unmesh._threads)
        with background_work():
            self._run(fn, args, kwargs)

    def done(self) -> bool:
        """Whether the result is ready (never needed for correctness: :meth:`result` waits)."""
        return self._thread is None or not self._thread.is_alive()

    def result(self) -> Any:
        """The function's value (waits for the thread); re-raises its exception."""
        if self._thread is not None:
            self._thread.join()
        if self._error is not None:
            raise self._error
        return self._value


#: Local sets of at least this many nodes are factorised in nested-dissection order.
LOCAL_ND_NODES = 400


def _local_factor(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, nodes: np.ndarray, kind: np.ndarray,
                  normal: np.ndarray) -> tuple[np.ndarray, Any]:
    """``(nodes, LU)`` of the filtered block ``S A_tt S + (I - S)`` on the sorted node set ``nodes``.

    Large local sets (the cut region after a few cuts: thousands of nodes) are ordered by
    nested dissection too: measured on the bunny-slicing benchmark, the local factorisations
    in minimum-degree order cost about as much as the global ones.
    """
    sub_ptr, sub_idx, sub = _sub_block_array(indptr, indices, blocks, nodes)
    kt = np.ascontiguousarray(kind[nodes], dtype=np.int64)
    m = len(nodes)
    if kt.any():  # the filter on the blocks (two sparse products cost a fifth of a local factorisation)
        sub = SK.filter_blocks(sub_ptr, sub_idx, sub, kt, np.ascontiguousarray(normal, dtype=np.float64))
    L = block_csr(sub_ptr, sub_idx, sub)
    perm = _local_order(sub_ptr, sub_idx) if m >= LOCAL_ND_NODES else None
    dof = None if perm is None else (3 * perm[:, None] + np.arange(3)).ravel()
    return nodes, Factorization(L, dof)


#: Local orders kept by :func:`_local_order` (the last ones made).
LOCAL_ORDERS = 8
_LOCAL_ORDERS: OrderedDict[bytes, np.ndarray] = OrderedDict()


def _local_order(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray | None:
    """:func:`nested_dissection` of a local set's pattern, remembered for the next :data:`LOCAL_ORDERS` patterns.

    The local sets of the contact region repeat from step to step (the same contact set on
    the same mesh: the bunny benchmark's 1,313 nodes in frames 1-12); METIS is deterministic,
    so a remembered order is the order it would make again, without waiting for the
    background thread's ordering of the whole mesh (METIS calls are serialised).
    """
    key = np.asarray(indptr, np.int64).tobytes() + np.asarray(indices, np.int64).tobytes()
    perm = _LOCAL_ORDERS.get(key)
    if perm is not None:
        _LOCAL_ORDERS.move_to_end(key)
        return perm
    perm = nested_dissection(indptr, indices)
    if perm is not None:
        _LOCAL_ORDERS[key] = perm
        while len(_LOCAL_ORDERS) > LOCAL_ORDERS:
            _LOCAL_ORDERS.popitem(last=False)
    return perm


def _sub_block_array(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, nodes: np.ndarray, *,
                     fast: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Node-level CSR ``(indptr, indices)`` and blocks (nnz, 9) of the submatrix on the sorted node set ``nodes``.

    ``fast``: a numba kernel over the rows of ``nodes`` only (the numpy version, ``fast=False``,
    passes over the whole pattern: ~12 ms per local factorisation on the bunny benchmark).
    """
    n = len(indptr) - 1
    if fast:
        sub_ptr, sub_idx, keep = SK.sub_pattern(np.asarray(indptr, np.int64), np.asarray(indices, np.int64),
                                                np.asarray(nodes, np.int64), n)
        return sub_ptr, sub_idx, blocks[keep]
    local = np.full(n, -1, np.int64)
    local[nodes] = np.arange(len(nodes))
    rows = np.repeat(np.arange(n), np.diff(indptr))
    keep = (local[rows] >= 0) & (local[indices] >= 0)
    lr, lc = local[rows[keep]], local[indices[keep]]
    sub_ptr = np.r_[0, np.cumsum(np.bincount(lr, minlength=len(nodes)))].astype(np.int64)
    return sub_ptr, lc, np.ascontiguousarray(blocks[keep])


def _sub_blocks(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray, nodes: np.ndarray) -> sp.csr_array:
    """The (3m, 3m) CSR submatrix of a 3×3-block CSR matrix on the sorted node set ``nodes`` (m,).

    Picks the blocks directly (no conversion of the whole matrix, which cost more than
    the local factorisation on the bunny benchmark).
    """
    return block_csr(*_sub_block_array(indptr, indices, blocks, nodes))


def block_csr(indptr: np.ndarray, indices: np.ndarray, blocks: np.ndarray) -> sp.csr_array:
    """The scalar (3n, 3n) CSR matrix of a node-level CSR pattern with 3×3 blocks (nnz, 9)."""
    n3 = 3 * (len(indptr) - 1)
    return sp.csr_array(sp.bsr_array((blocks.reshape(-1, 3, 3), indices, indptr), shape=(n3, n3)).tocsr())
