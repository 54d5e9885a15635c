"""What depends on a matrix's pattern alone, computed once per matrix object and kept while
it lives: a validated fit solves subsets of the same load blocks dozens of times, and its
forked workers inherit what the caller built before the fork. The network's one map
k -> K (harness/linalg/stiffness.py) serves every load set and shared group of its fits."""

from __future__ import annotations

import weakref

import numpy as np
import scipy.sparse as sp

from harness.linalg.stiffness import stiffness_map

_PER_MATRIX: dict = {}  # id(B) -> (weakref to B, {name: value})


def network_map(network: sp.csc_matrix):
    """(pattern, map k -> K.data) of a network's whole K (harness/linalg/stiffness.py), kept
    per matrix: one map for all its load sets and shared groups, built before a pool of fits
    forks (:meth:`FitProblem.prepare`) so that its workers share it, not one each."""
    return per_matrix(network, "kmap", lambda: stiffness_map(network))


def network_values(network: sp.csc_matrix, k: np.ndarray) -> np.ndarray:
    """The whole K's values at k (:func:`network_map`), kept for the last k: the load sets
    of one evaluation restrict one product."""
    last = per_matrix(network, "last k", dict)
    if last.get("k") is None or not np.array_equal(last["k"], k):
        last.update(k=np.array(k, float), data=network_map(network)[1] @ k)
    return last["data"]


def per_matrix(B, name: str, make):
    """``make()`` once per matrix object B and name, kept while B lives: the stiffness
    map, the orderings and the symbolic factorisation depend on B's pattern alone, and a
    validated fit solves subsets of the same blocks dozens of times."""
    entry = _PER_MATRIX.get(id(B))
    if entry is None or entry[0]() is not B:
        entry = (weakref.ref(B), {})
        _PER_MATRIX[id(B)] = entry
        weakref.finalize(B, _PER_MATRIX.pop, id(B), None)
    store = entry[1]
    if name not in store:
        store[name] = make()
    return store[name]
