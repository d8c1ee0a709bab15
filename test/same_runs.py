"""Two runs of the same code alike: every float within :data:`SAME`, everything else (names,
outcomes, counts, keys) equal. Determinism checks compare so: within round-off, not to the bit."""

import numpy as np

#: [the floats' own unit] what two runs of one seed may differ by
SAME = 1e-9


def assert_same(a, b, where='document'):
    """``a`` and ``b`` (dicts, lists, tuples, numbers, strings, arrays) alike: every float
    within :data:`SAME`, everything else equal."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), where
        for key in a:
            assert_same(a[key], b[key], f'{where}.{key}')
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            assert_same(x, y, f'{where}[{i}]')
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, where
        if a.dtype.kind == 'f' or b.dtype.kind == 'f':
            np.testing.assert_allclose(a, b, rtol=0, atol=SAME, err_msg=where)
        else:
            np.testing.assert_array_equal(a, b, err_msg=where)
    elif isinstance(a, float) or isinstance(b, float):
        assert not isinstance(a, bool) and not isinstance(b, bool), where
        np.testing.assert_allclose(a, b, rtol=0, atol=SAME, err_msg=where)
    else:
        assert a == b, where
