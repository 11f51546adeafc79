"""The one CSR builder (:mod:`unmesh._csr_kernels`) against numpy's stable argsort."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from unmesh._csr_kernels import counting_sort_csr, csr_rows


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 9), max_size=60), st.integers(0, 5))
def test_counting_sort_csr_is_a_stable_argsort_with_searchsorted_offsets(keys, extra):
    keys = np.array(keys, dtype=np.int64)
    nkeys = (int(keys.max()) + 1 if keys.size else 0) + extra
    order, offsets = counting_sort_csr(keys, nkeys)
    ref = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(order, ref)
    np.testing.assert_array_equal(offsets, np.searchsorted(keys[ref], np.arange(nkeys + 1)))
    assert order.dtype == offsets.dtype == np.int64


def test_csr_rows_repeats_each_row_by_its_length():
    offsets = np.array([0, 3, 3, 4, 7], dtype=np.int64)
    np.testing.assert_array_equal(csr_rows(offsets), np.repeat(np.arange(4), np.diff(offsets)))
    assert csr_rows(np.zeros(1, np.int64)).shape == (0,)
