"""The coupled step's per-node kernels of orchestrator/coupling/operator_rows.py against the numpy
expressions they replace (embedded.EmbeddedCoupling.solve / background_correction): the same
results bit for bit (numpy's summation orders: sequential axis-0 sums, pairwise full sums)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from orchestrator.coupling.operator_rows import (correction_means, impulse_sums, oscillation, pairwise_sum, row_means,
                                                 surface_load, transpose_product)


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 16, 17, 127, 128, 129, 130, 1000, 8193, 88516, 300001])
def test_pairwise_sum_is_numpys(n):
    a = np.random.default_rng(n).normal(size=n) * 10.0 ** np.random.default_rng(n + 1).uniform(-8, 8, n)
    assert 0.0 + pairwise_sum(a, 0, n) == np.sum(a)
    if n > 3:   # an offset range: the same as numpy's sum of the slice
        assert 0.0 + pairwise_sum(a, 3, n - 3) == np.sum(a[3:])


@pytest.mark.parametrize("dim", [2, 3])
def test_step_kernels_match_the_numpy_expressions(dim):
    rng = np.random.default_rng(dim)
    nz, ns = 37, 4000
    B = sp.random(nz, ns, density=0.01, random_state=3, format="csr")
    B.sort_indices()
    area = rng.uniform(0.5, 1.5, nz)
    area[3] = 0.0
    R = rng.normal(size=(nz, dim))
    vstar = rng.normal(size=(ns, dim))
    free = (rng.uniform(size=(ns, dim)) > 0.1).astype(float)
    mass = rng.uniform(1.0, 2.0, ns)
    load, v_f = surface_load(B.indptr, B.indices, B.data, R, area, ns, 0.37, vstar, free, mass)
    safe = np.where(area > 0.0, area, 1.0)
    F = -transpose_product(B.indptr, B.indices, B.data, R / safe[:, None], ns)
    assert np.array_equal(load, 0.37 * F)
    assert np.array_equal(v_f, vstar + 0.37 * F * free / mass[:, None])
    jf = rng.normal(size=(ns, dim))
    imp, total = impulse_sums(load, jf)
    assert np.array_equal(imp, load + jf) and np.array_equal(total, (load + jf).sum(axis=0))
    v_old, v_new = rng.normal(size=(ns, dim)), rng.normal(size=(ns, dim))
    vh, vb, work = correction_means(B.indptr, B.indices, B.data, area, v_old, v_new, imp)
    vbar = 0.5 * (v_old + v_new)
    assert np.array_equal(vh, row_means(B.indptr, B.indices, B.data, v_new, area))
    assert np.array_equal(vb, row_means(B.indptr, B.indices, B.data, vbar, area))
    assert work == np.sum(imp * vbar)


@pytest.mark.parametrize("k", [1, 2, 3])
def test_oscillation_is_the_numpy_form(k):
    rng = np.random.default_rng(k)
    nz = 300
    lam = rng.normal(size=(nz, k))
    normal = rng.normal(size=(nz, 2))
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    pairs = np.sort(rng.integers(0, nz, (500, 2)), axis=1)
    keep = pairs[np.einsum("ij,ij->i", normal[pairs[:, 0]], normal[pairs[:, 1]]) > 0.5]
    ref = np.mean(np.linalg.norm(lam[keep[:, 0]] - lam[keep[:, 1]], axis=1)) / np.mean(np.linalg.norm(lam, axis=1))
    assert oscillation(lam, pairs, normal) == ref
    assert oscillation(np.zeros((nz, k)), pairs, normal) == 0.0
    assert oscillation(lam, pairs[:0], normal) == 0.0
