"""Sparse symmetric factorisations by MKL PARDISO: ordering once per graph, values many times.

Alternating minimisation refactorises the matrices of a_j and b_j twice per iteration on a
fixed graph, and Newton's method its Hessian once per step. PARDISO's supernodal L D Lᵀ
factorisation and back-substitution are faster on these meshes than NGSolve's sparse Cholesky
(``docs/paper-example.md`` has the measured ratios), and its factorisation of a symmetric
indefinite matrix counts the negative eigenvalues (Sylvester's law of inertia), which tells
Newton's method whether its Hessian has negative curvature at all.

NGSolve registers an ``inverse="pardiso"`` of its own when the ``mkl`` wheel is installed (and
makes it the default of ``Inverse()``); it extracts the upper triangle and copies the matrix on
every factorisation and refines every solution iteratively, which made it no faster than the
sparse Cholesky here. :class:`Pardiso` takes the upper triangle's graph once and its values as
an array. MKL comes from the ``mkl`` wheel (x86-64 only); without it :data:`AVAILABLE` is false
and ngat uses NGSolve's sparse Cholesky.
"""

from __future__ import annotations

import ctypes
import importlib.metadata
import os
import weakref
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from functools import cache
from typing import Any, TypeVar

import numpy as np
import scipy.sparse as sp
from ngsolve import BitArray
from ngsolve.la import BaseMatrix, BaseVector, SparseMatrixd

from ngat.forms import sparse_from_coo
from ngat.timing import linear_solver

__all__ = [
    "AVAILABLE",
    "LowerCholesky",
    "dof_ordering",
    "symmetric_factor",
    "MKL_CBWR_AUTO",
    "TWO_LEVEL",
    "Pardiso",
    "background_ordering",
    "in_background",
    "PardisoError",
    "PardisoInverse",
    "SLOTS",
    "sparse_inverse",
    "vertex_ordering",
    "wait_background",
]


def _load_mkl() -> ctypes.CDLL | None:
    """Return MKL's runtime library from the ``mkl`` wheel, or ``None`` if it is not installed."""
    try:
        files = importlib.metadata.distribution("mkl").files or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for file in files:
        if "mkl_rt" in file.name:
            try:
                return ctypes.CDLL(str(file.locate()))
            except OSError:
                return None
    return None


# Loaded at import, with the OpenMP library MKL's threading layer loads on first use, so that
# the thread limits of ngat.threads reach both; MKL uses the threads it is given, no fewer.
_MKL = _load_mkl()
AVAILABLE = _MKL is not None
"""Whether MKL PARDISO can be used."""
MKL_CBWR_AUTO = 2
"""MKL's conditional numerical reproducibility on the processor's own code branch
(``MKL_CBWR=AUTO``). Without it, on processors with AVX-512, factorisations on one thread and on
two differ in the last bits (5e−15 at 58k DOFs); with it they agree at the same speed."""
if _MKL is not None:
    if "MKL_CBWR" not in os.environ:
        _MKL.MKL_CBWR_Set(MKL_CBWR_AUTO)
    _MKL.MKL_Get_Max_Threads()
    _MKL.MKL_Set_Dynamic(0)

TWO_LEVEL = 10
"""PARDISO's two-level factorisation (``iparm[23]``), used for positive definite matrices on one
thread. Against the classic algorithm on two threads, on P1 matrices of 26k / 58k / 116k DOFs:
numeric factorisation 7.7 / 23 / 52 ms against 7.4 / 22 / 44 ms, back-substitution 1.2 / 3.1 /
6.3 ms against 4.9 / 11.5 / 24 ms. On two threads it is not repeatable to the last bit, and
for symmetric indefinite matrices it reports no inertia (``iparm[22]`` stays 0), so Newton's
Hessian keeps the classic algorithm on MKL's threads."""

T = TypeVar("T")

_INT = ctypes.POINTER(ctypes.c_int32)
if _MKL is not None:
    _MKL.pardisoinit.restype = None
    _MKL.pardisoinit.argtypes = [ctypes.c_void_p, _INT, _INT]
    _MKL.pardiso.restype = None
    _MKL.pardiso.argtypes = [ctypes.c_void_p, *[_INT] * 5, ctypes.c_void_p, _INT, _INT, _INT, _INT,
                             _INT, _INT, ctypes.c_void_p, ctypes.c_void_p, _INT]  # fmt: skip

_ERRORS = {
    -1: "input inconsistent",
    -2: "not enough memory",
    -3: "reordering problem",
    -4: "zero pivot, numerical factorisation or iterative refinement problem",
    -10: "no license file found",
    -12: "wrong input (order or type of the matrix)",
}


class PardisoError(RuntimeError):
    """PARDISO returned an error code."""


def _int(value: int) -> ctypes.c_int32:
    return ctypes.c_int32(value)


class Pardiso:
    """L D Lᵀ factorisation of a symmetric sparse matrix given by its upper triangle.

    The ordering and symbolic analysis (METIS nested dissection) happen once, in the
    constructor; :meth:`factorise` computes the numeric factorisation for new values on the
    same graph and :meth:`solve` back-substitutes. A positive definite matrix is factorised
    on one thread by the two-level algorithm (:data:`TWO_LEVEL`), an indefinite one on MKL's
    threads (:class:`ngat.threads.FixedThreads`), whose results are the same to the last bit
    with one thread or two (:data:`MKL_CBWR_AUTO`).

    Parameters
    ----------
    indptr, indices
        CSR graph of the upper triangle (diagonal included, columns sorted in each row).
    definite
        Whether the matrix is positive definite (Cholesky) or only symmetric (Bunch–Kaufman
        pivoting, and :attr:`negative_eigenvalues` is counted).
    ordering
        A fill-reducing ordering to use (row ``ordering[i]`` is the i-th pivot); default
        METIS's, computed here. The analysis with a given ordering costs about a quarter of
        one that computes it.
    sequential
        Whether every phase runs on one thread with PARDISO's two-level factorisation
        (:data:`TWO_LEVEL`); default for positive definite matrices. Otherwise the phases run
        on MKL's threads (:class:`ngat.threads.FixedThreads`) with the classic algorithm.
    background
        Run the analysis in the background (sequential only; see :meth:`factorise`).
    threaded_ordering
        In the analysis of a sequential factorisation, run METIS's OpenMP version on MKL's
        threads (:func:`vertex_ordering`); the same ordering as the sequential version.
    slots
        Factorisations kept at once on the one analysis (PARDISO's ``maxfct``): matrices with
        this graph, each factorised into a slot of its own (1 … ``slots``).

    Attributes
    ----------
    ordering : numpy.ndarray
        The ordering in use.
    """

    def __init__(
        self,
        indptr: np.ndarray,
        indices: np.ndarray,
        definite: bool,
        ordering: np.ndarray | None = None,
        sequential: bool | None = None,
        background: bool = False,
        threaded_ordering: bool = False,
        slots: int = 1,
    ) -> None:
        if not AVAILABLE:
            raise PardisoError("MKL PARDISO is not available: pip install mkl (x86-64 only)")
        self.n = len(indptr) - 1
        self._indptr = np.ascontiguousarray(indptr, dtype=np.int32)
        self._indices = np.ascontiguousarray(indices, dtype=np.int32)
        self._values = np.zeros((slots, len(indices)))
        self._rhs, self._out = np.zeros(self.n), np.zeros(self.n)
        self._mtype = 2 if definite else -2
        self._handle = np.zeros(64, dtype=np.int64)
        self.iparm = np.zeros(64, dtype=np.int32)
        _MKL.pardisoinit(
            self._handle.ctypes.data, ctypes.byref(_int(self._mtype)), _ptr(self.iparm)
        )
        self._sequential = definite if sequential is None else sequential
        if self._sequential:
            self.iparm[23] = TWO_LEVEL
        # METIS's nested dissection; with several threads its OpenMP version, which is faster
        # (0.32 against 0.49 s at 120k DOFs) and gave the same ordering in every comparison.
        self._threaded_ordering = threaded_ordering and ordering is None
        parallel = (threaded_ordering or not self._sequential) and _MKL.MKL_Get_Max_Threads() > 1
        self.iparm[1] = 3 if ordering is None and parallel else 2
        self.iparm[7] = 0  # iterative refinement only after perturbed pivots
        self.iparm[34] = 1  # zero-based indices
        self.iparm[4] = 2 if ordering is None else 1  # return METIS's ordering, or use this one
        self.ordering = np.zeros(self.n, dtype=np.int32)
        if ordering is not None:
            self.ordering[:] = ordering
        self._pending: list[Future] = []  # phases under way in the background, in order
        if self.n:
            self._run(background, self._call, 11)
            # Released when the object goes, or at exit before the modules are torn down.
            weakref.finalize(
                self, _release, self._handle, self._mtype, self.iparm, self._pending, slots
            )

    def _call(self, phase: int, slot: int = 1) -> None:
        """Run PARDISO's ``phase`` on ``slot``."""
        values = self._values[slot - 1]
        arrays = (values, self._indptr, self._indices, self.ordering, self._rhs, self._out)
        factors = (len(self._values), slot)
        if not self._sequential:
            wait_background()  # MKL's threads need both cores
            _pardiso(self._handle, self._mtype, phase, self.iparm, arrays, factors)
            return
        # 0: the global count, MKL's threads (ngat.threads.FixedThreads), for METIS alone.
        metis = phase == 11 and self._threaded_ordering
        threads = _MKL.MKL_Set_Num_Threads_Local(0 if metis else 1)
        try:
            _pardiso(self._handle, self._mtype, phase, self.iparm, arrays, factors)
        finally:
            _MKL.MKL_Set_Num_Threads_Local(threads)

    def factorise(self, values: np.ndarray, background: bool = False, slot: int = 1) -> None:
        """Compute the numeric factorisation for the upper triangle's ``values`` into ``slot``.

        With ``background`` the factorisation runs in a worker thread (:func:`_worker`) and
        this returns at once: the caller computes on meanwhile, and the next call that needs
        the factors waits for them. PARDISO runs outside Python's global interpreter lock, so
        the two overlap on two cores; the factors are the same to the last bit. ``values``
        must not change until then. Only a sequential factorisation (the class's
        ``sequential``) runs in the background: one on MKL's threads needs both cores.
        """
        if self.n:
            self._run(background, self._factorise, values, slot)

    def _factorise(self, values: np.ndarray, slot: int) -> None:
        self._values[slot - 1] = values
        self._call(22, slot)

    def _run(self, background: bool, function: Callable[..., None], *args: Any) -> None:
        """Run ``function(*args)`` now, or in the background after the phases under way there."""
        if background and self._sequential:
            self._pending.append(in_background(function, *args))
        else:
            _wait(self._pending)
            function(*args)

    def solve(self, rhs: np.ndarray, slot: int = 1) -> np.ndarray:
        """Return A⁻¹ ``rhs`` with the last factorisation in ``slot``."""
        _wait(self._pending)
        self._rhs[:] = rhs
        if self.n:
            self._call(33, slot)
        return self._out.copy()

    @property
    def negative_eigenvalues(self) -> int:
        """Negative eigenvalues of the matrix factorised last, in any slot (indefinite only)."""
        _wait(self._pending)
        return int(self.iparm[22])


@cache
def _worker() -> ThreadPoolExecutor:
    """Return the one thread that runs background factorisations, in the order submitted."""
    return ThreadPoolExecutor(max_workers=1, thread_name_prefix="ngat-pardiso")


# A forked child has none of its parent's threads: it makes a worker of its own.
os.register_at_fork(after_in_child=_worker.cache_clear)


def in_background(function: Callable[..., T], *args: Any) -> Future:
    """Run ``function(*args)`` in the worker thread after the phases under way; return its future.

    For numpy work of a new mesh that the worker can take while the main thread builds the
    rest (numpy releases Python's lock in its loops).
    """
    return _worker().submit(function, *args)


def wait_background() -> None:
    """Wait until no factorisation runs in the background, before work on several threads.

    Threads that wait for each other at every step (MKL's, NGSolve's TaskManager) slow down
    many times when a core they need is busy (:class:`ngat.threads.CoreUse`).
    """
    if _worker.cache_info().currsize:
        _worker().submit(int).result()


def _wait(pending: list[Future]) -> None:
    """Wait for the phases under way in ``pending``, in order (raising their errors)."""
    while pending:
        pending.pop(0).result()


def _release(
    handle: np.ndarray, mtype: int, iparm: np.ndarray, pending: list[Future], slots: int
) -> None:
    """Free PARDISO's memory of a factorisation once no phase of it is under way."""
    try:
        _wait(pending)
    finally:
        _pardiso(handle, mtype, -1, iparm, factors=(slots, 1))


def _ptr(array: np.ndarray):
    """Return a pointer to an int32 array's data."""
    return array.ctypes.data_as(_INT)


def _pardiso(
    handle: np.ndarray, mtype: int, phase: int, iparm: np.ndarray, arrays=(), factors=(1, 1)
) -> None:
    """Call PARDISO's ``phase`` with one right-hand side.

    ``arrays`` are the values, row pointers, columns, ordering, right-hand side and solution;
    none for the release (phase −1). ``factors``: PARDISO's ``maxfct`` (the factorisations
    kept on the analysis) and ``mnum`` (the one this call is about). Timed on
    :data:`ngat.timing.linear_solver`, in whichever thread it runs.
    """
    values, indptr, indices, ordering, rhs, out = arrays or (None,) * 6
    error = _int(0)
    with linear_solver():
        _MKL.pardiso(
            handle.ctypes.data, ctypes.byref(_int(factors[0])), ctypes.byref(_int(factors[1])),
            ctypes.byref(_int(mtype)), ctypes.byref(_int(phase)),
            ctypes.byref(_int(0 if rhs is None else len(rhs))),
            None if values is None else values.ctypes.data,
            None if indptr is None else _ptr(indptr), None if indices is None else _ptr(indices),
            None if ordering is None else _ptr(ordering), ctypes.byref(_int(1)), _ptr(iparm),
            ctypes.byref(_int(0)),
            None if rhs is None else rhs.ctypes.data, None if out is None else out.ctypes.data,
            ctypes.byref(error),
        )  # fmt: skip
    if error.value:
        reason = _ERRORS.get(error.value, "see MKL's PARDISO documentation")
        raise PardisoError(f"PARDISO phase {phase} failed with error {error.value}: {reason}")


SLOTS = 3
"""Factorisations kept on one analysis of a :class:`PardisoInverse`: a_j, b_j and the bounded
v-step's on a mesh's P1 graph (:class:`ngat.halfsteps.HalfStepSolvers`)."""


class PardisoInverse(BaseMatrix):
    """A⁻¹ of an NGSolve sparse matrix on its free DOFs by :class:`Pardiso`, 0 on the others.

    Used like ``matrix.Inverse(free)``: ``inverse * x`` solves and :meth:`Update` refactorises
    with the matrix's current values (same graph). The matrix may store its whole graph or only
    the entries on and below the diagonal; those are the ones read.

    Every DOF stays in the factorisation: the rows and columns of those that are not free are
    replaced by the identity's (their couplings dropped), so that the solution is 0 there and
    the free block is factorised as it is. One symbolic analysis of the graph thus serves
    every free set, and matrices on one graph share it (``analysis``), each factorised into a
    slot of its own: a_j and b_j of a scalar u and the bounded v-step's free sets on a mesh
    (:class:`ngat.halfsteps.HalfStepSolvers`) need one analysis where they needed one each
    (at 57k DOFs an analysis costs 37–45 ms, about as much as a factorisation).

    Parameters
    ----------
    matrix
        The sparse matrix; its values may change between :meth:`Update` calls.
    free
        Boolean mask of the free DOFs.
    definite
        Whether the matrix is positive definite on the free DOFs (see :class:`Pardiso`).
    ordering
        A fill-reducing ordering of the vertices (:func:`vertex_ordering`) when the matrix's
        DOFs are k per vertex, component-major (DOF c nv + i is component c at vertex i):
        the DOFs are ordered vertex by vertex in this order. Default METIS's ordering of the
        matrix itself, computed here.
    background
        Analyse and factorise in the background (:meth:`Pardiso.factorise`).
    analysis
        An inverse of a matrix with the same graph whose analysis this one shares (then
        ``definite`` and ``ordering`` are its).
    slot
        The slot of the shared analysis this inverse factorises into, 1 … :data:`SLOTS`;
        inverses sharing an analysis need slots of their own.
    """

    def __init__(
        self,
        matrix: SparseMatrixd,
        free: np.ndarray,
        definite: bool = True,
        ordering: np.ndarray | None = None,
        background: bool = False,
        analysis: PardisoInverse | None = None,
        slot: int = 1,
    ) -> None:
        super().__init__()
        self.matrix = matrix
        self.free = np.array(free, dtype=bool)
        if analysis is None:
            self._take, indptr, indices = _upper_triangle(matrix, np.arange(matrix.height))
            if ordering is not None:
                ordering = dof_ordering(ordering, matrix.height)
            self.factor = Pardiso(
                indptr, indices, definite, ordering, background=background, slots=SLOTS
            )
            self._rows = np.repeat(np.arange(matrix.height), np.diff(indptr))
        else:
            if analysis.matrix.height != matrix.height or analysis.matrix.nze != matrix.nze:
                raise ValueError("an analysis is shared by matrices of one graph only")
            self._take, self.factor, self._rows = analysis._take, analysis.factor, analysis._rows
        if not 1 <= slot <= SLOTS:
            raise ValueError(f"slot {slot} is not one of 1 … {SLOTS}")
        self.slot = slot
        fixed = ~self.free
        self._dropped = np.flatnonzero(fixed[self._rows] | fixed[self.factor._indices])
        self._diagonal = self.factor._indptr[:-1][fixed]  # a row of the upper triangle starts there
        self.Update(background)

    def Update(self, background: bool = False) -> None:
        """Refactorise with the matrix's current values, in the ``background`` if asked.

        :meth:`Pardiso.factorise` says what runs in the background. Values that are not
        finite are not factorised: the solves then give NaN, as NGSolve's
        sparse Cholesky does, and the iteration that produced them stops with its message.
        """
        values = self.matrix.AsVector().FV().NumPy()[self._take]
        values[self._dropped] = 0.0
        values[self._diagonal] = 1.0
        self.finite = bool(np.isfinite(values).all())
        if self.finite:
            self.factor.factorise(values, background, self.slot)

    def Mult(self, x: BaseVector, y: BaseVector) -> None:
        """Set y = A⁻¹ x on the free DOFs and 0 on the others."""
        out = y.FV().NumPy()
        if self.finite:
            out[:] = self.factor.solve(np.where(self.free, x.FV().NumPy(), 0.0), self.slot)
        else:
            out[:] = np.nan
        out[~self.free] = 0.0

    def Height(self) -> int:
        """Return the matrix's height."""
        return self.matrix.height

    def Width(self) -> int:
        """Return the matrix's width."""
        return self.matrix.width

    def CreateColVector(self) -> BaseVector:
        """Return a vector like the matrix's columns."""
        return self.matrix.CreateColVector()

    def CreateRowVector(self) -> BaseVector:
        """Return a vector like the matrix's rows."""
        return self.matrix.CreateRowVector()

    @property
    def negative_eigenvalues(self) -> int:
        """Negative eigenvalues of the last factorised matrix on the free DOFs."""
        return self.factor.negative_eigenvalues


def _upper_triangle(matrix: SparseMatrixd, number: np.ndarray) -> tuple[np.ndarray, ...]:
    """Return where the upper triangle's entries sit in ``matrix``'s values, and its CSR graph.

    Only the rows and columns with ``number`` ≥ 0 are kept, renumbered by it. The matrix may
    store its whole graph or only the entries on and below the diagonal: the lower triangle's
    entry (a, b) is read as the upper triangle's (b, a).
    """
    _, cols, rowptr = matrix.CSR()
    cols, rowptr = np.asarray(cols, dtype=np.int64), np.asarray(rowptr, dtype=np.int64)
    rows = np.repeat(np.arange(len(rowptr) - 1), np.diff(rowptr))
    lower = np.flatnonzero((cols <= rows) & (number[rows] >= 0) & (number[cols] >= 0))
    # The lower triangle in CSR (rows ascending: number is increasing on the kept rows), with
    # each entry's position as its value; its CSC is the upper triangle's CSR, built by a
    # counting sort that keeps the rows sorted in each column.
    n = number.max() + 1
    counts = np.bincount(number[rows[lower]], minlength=n)
    lower_csr = sp.csr_matrix(
        (lower, number[cols[lower]], np.concatenate([[0], np.cumsum(counts)])), shape=(n, n)
    )
    upper = lower_csr.tocsc()
    return upper.data, upper.indptr, upper.indices


def vertex_ordering(matrix: SparseMatrixd) -> np.ndarray:
    """Return METIS's fill-reducing ordering of a P1 matrix's graph (vertex ``ordering[i]`` first).

    One per mesh serves every factorisation on it (:class:`PardisoInverse`'s ``ordering``):
    a_j and b_j with their free DOFs, Newton's Hessian with its DOFs vertex by vertex. METIS
    runs in its OpenMP version on MKL's threads, in the background as well
    (:func:`background_ordering`), where a new mesh's first factorisation waits for it: on
    two threads it is faster than the sequential version (0.10 against 0.15 s at 114k
    elements, 0.15 against 0.22 s at 169k) and gave the same ordering in every comparison
    (``tests/test_pardiso.py``); the paper's example waits 1.25 instead of 1.79 s in all
    for its orderings, to the same bits.

    The analysis that computed it is released, though b_j on all DOFs could factorise on it (one
    analysis of 15–25 ms fewer per mesh): factorisations on an analysis that ran METIS, in
    either version, are not repeatable to the last bit (two of six differed at 49k DOFs, and
    refactorising on one analysis differed too), those with the ordering given are, and a
    resumed run must repeat the uninterrupted one.
    """
    return _ordering(*_upper_triangle(matrix, np.arange(matrix.height))[1:])


def background_ordering(graph: Callable[[], tuple[np.ndarray, np.ndarray]]) -> Future:
    """Start METIS's ordering of the upper triangle's CSR graph ``graph()`` in the worker thread.

    The graph is built there too (:func:`_worker`): a new mesh's set-up goes on meanwhile, and
    its first factorisation waits for the ordering (:func:`vertex_ordering` gives the same).
    """
    return in_background(lambda: _ordering(*graph()))


def _ordering(indptr: np.ndarray, indices: np.ndarray) -> np.ndarray:
    """Return METIS's ordering of the graph of an upper triangle, computed on MKL's threads."""
    return Pardiso(
        indptr, indices, definite=True, sequential=True, threaded_ordering=True
    ).ordering.astype(np.int64)


def dof_ordering(ordering: np.ndarray, size: int) -> np.ndarray:
    """Return the ordering of ``size`` DOFs, k per vertex, from the vertices' ``ordering``.

    The DOFs are component-major (DOF c nv + i is component c at vertex i) and are ordered
    vertex by vertex: the k DOFs of a vertex one after the other.
    """
    components = np.arange(size // len(ordering))
    return (ordering[:, None] + len(ordering) * components).ravel()


def symmetric_factor(
    indptr: np.ndarray,
    indices: np.ndarray,
    definite: bool = True,
    ordering: np.ndarray | None = None,
) -> Pardiso | LowerCholesky:
    """Return a factorisation of the symmetric matrices with this graph of the upper triangle.

    :class:`Pardiso` with MKL, else :class:`LowerCholesky`: both take the values of the entries
    on and above the diagonal in the CSR order of ``indptr``, ``indices`` (sorted rows) with
    ``factorise`` and solve with ``solve``; only PARDISO counts ``negative_eigenvalues``.
    ``ordering`` is PARDISO's (NGSolve's factorisation computes its own).
    """
    if AVAILABLE:
        return Pardiso(indptr, indices, definite, ordering)
    return LowerCholesky(indptr, indices)


class LowerCholesky:
    """NGSolve's sparse Cholesky factorisation (L D Lᵀ) with the interface of :class:`Pardiso`.

    NGSolve's factorisation reads the entries on and below the diagonal: the matrix holds the
    mirror of the given upper triangle, and each factorisation copies the values into it in its
    own order (found once, by giving the constructor the entries' numbers as values).

    Parameters
    ----------
    indptr, indices
        CSR graph of the upper triangle, rows sorted.
    """

    def __init__(self, indptr: np.ndarray, indices: np.ndarray) -> None:
        n = len(indptr) - 1
        rows = np.repeat(np.arange(n), np.diff(indptr))
        numbers = np.arange(len(indices), dtype=float)
        self.matrix = sparse_from_coo(indices, rows, numbers, n, n)
        self._order = self.matrix.AsVector().FV().NumPy().astype(np.int64)
        self._inverse = None
        self._rhs, self._out = self.matrix.CreateColVector(), self.matrix.CreateColVector()

    def factorise(self, values: np.ndarray) -> None:
        """Factorise the matrix with these values of the upper triangle."""
        self.matrix.AsVector().FV().NumPy()[:] = values[self._order]
        if self._inverse is None:
            self._inverse = self.matrix.Inverse(inverse="sparsecholesky")
        else:
            self._inverse.Update()

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """Return A⁻¹ ``rhs`` with the last factorisation."""
        self._rhs.FV().NumPy()[:] = rhs
        self._out.data = self._inverse * self._rhs
        return self._out.FV().NumPy().copy()


def sparse_inverse(
    matrix: SparseMatrixd,
    free: np.ndarray | None = None,
    definite: bool = True,
    ordering: np.ndarray | None = None,
    background: bool = False,
    analysis: Any = None,
    slot: int = 1,
):
    """Return A⁻¹ on the free DOFs: :class:`PardisoInverse` with MKL, else NGSolve's Cholesky.

    Both refactorise with ``Update()`` on the same graph and solve with ``inverse * x``.
    NGSolve's sparse Cholesky reads the entries on and below the diagonal as well and factorises
    indefinite matrices (L D Lᵀ) too, but counts no negative eigenvalues, and computes its own
    ordering (``ordering`` is PARDISO's) and analysis (``analysis``, another inverse on the same
    graph, and ``slot`` are PARDISO's too: :class:`PardisoInverse`). ``background``: PARDISO's
    analysis and factorisation of a definite matrix run on while the caller computes
    (:meth:`Pardiso.factorise`).
    """
    if free is None:
        free = np.ones(matrix.height, dtype=bool)
    if AVAILABLE:
        shared = analysis if isinstance(analysis, PardisoInverse) else None
        return PardisoInverse(matrix, free, definite, ordering, background, shared, slot)
    return matrix.Inverse(BitArray(free), inverse="sparsecholesky")
