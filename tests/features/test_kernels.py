"""Feature kernels against independent references: antropy, numpy, closed forms."""

import antropy
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from aptkt import features

RNG = np.random.default_rng(1234)


def rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300))


@pytest.mark.parametrize(
    "shape,axis", [((5000,), -1), ((7, 3, 5000), -1), ((7, 400, 3), 1), ((50, 6), 0)]
)
def test_hjorth_matches_antropy(shape, axis):
    x = RNG.normal(size=shape) * 0.01 + 1.0  # an accelerometer axis: gravity plus vibration
    activity, mobility, complexity = features.hjorth(x, axis=axis)
    mob_ref, com_ref = antropy.hjorth_params(x, axis=axis)
    assert rel(mobility, mob_ref) < 1e-10
    assert rel(complexity, com_ref) < 1e-10
    assert rel(activity, np.var(x, axis=axis)) < 1e-10


def test_hjorth_on_strided_views_equals_contiguous_copy():
    base = RNG.normal(size=(3, 7, 2000))
    view = base.transpose(1, 0, 2)[:, :, ::3]  # non-contiguous, negative-free strides
    assert not view.flags.c_contiguous
    got = features.hjorth(view)
    want = features.hjorth(np.ascontiguousarray(view))
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)
    reversed_view = base[:, :, ::-1]
    mob_ref, com_ref = antropy.hjorth_params(np.ascontiguousarray(reversed_view), axis=-1)
    assert rel(features.hjorth(reversed_view)[1], mob_ref) < 1e-10


@pytest.mark.parametrize("dtype", [np.float32, np.int16])
def test_hjorth_accepts_raw_sample_types(dtype):
    x = (RNG.normal(size=(7, 3, 800)) * 300).astype(dtype)
    got = features.hjorth(x)
    mob_ref, com_ref = antropy.hjorth_params(x.astype(np.float64), axis=-1)
    assert rel(got[1], mob_ref) < 1e-10
    assert rel(got[2], com_ref) < 1e-10


def test_one_dimensional_input_gives_floats():
    a, m, c = features.hjorth(np.sin(np.arange(100) * 0.3))
    assert all(isinstance(v, float) for v in (a, m, c))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_input_is_named(bad):
    x = RNG.normal(size=(2, 3, 50))
    x[1, 0, 17] = bad
    with pytest.raises(ValueError, match=r"x contains a non-finite value .* at index \(1, 0, 17\)"):
        features.hjorth(x)
    with pytest.raises(ValueError, match="acc contains"):
        features.texture_descriptor(x)
    with pytest.raises(ValueError, match="force contains"):
        features.mean_force(x)
    with pytest.raises(ValueError, match="temp contains"):
        features.thermal_curve(x)


def test_shape_errors_are_value_errors():
    with pytest.raises(ValueError, match="at least 3 samples"):
        features.hjorth(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="out of bounds"):
        features.hjorth(np.zeros((4, 5)), axis=2)
    with pytest.raises(ValueError, match="3 acceleration axes"):
        features.axis_pair_correlation(np.zeros((2, 4, 10)))
    with pytest.raises(ValueError, match=r"\(cells, 3, time\)"):
        features.texture_descriptor(np.zeros((3, 10)))
    with pytest.raises(TypeError):
        features.hjorth(np.array(["a", "b", "c"]))


def test_axis_pair_correlation_matches_numpy():
    acc = RNG.normal(size=(7, 3, 500))
    acc[:, 1] += 0.5 * acc[:, 0]
    got = features.axis_pair_correlation(acc)
    for c in range(7):
        r = np.corrcoef(acc[c])
        np.testing.assert_allclose(got[c], [r[0, 1], r[1, 2], r[0, 2]], rtol=1e-12, atol=1e-14)
    # Time first, channels last.
    got_t = features.axis_pair_correlation(acc.transpose(0, 2, 1), axis=1, channel_axis=2)
    np.testing.assert_allclose(got_t, got, rtol=1e-13)


def test_texture_descriptor_matches_reference():
    acc = RNG.normal(size=(7, 3, 1250)) * [[[0.01], [0.02], [0.005]]] + [[[0.0], [0.0], [-1.0]]]
    td = features.texture_descriptor(acc)
    assert td.shape == (features.TEXTURE_DIM,) == (len(features.TEXTURE_NAMES),)
    mob, com = antropy.hjorth_params(acc, axis=-1)
    corr = np.array(
        [[np.corrcoef(c)[0, 1], np.corrcoef(c)[1, 2], np.corrcoef(c)[0, 2]] for c in acc]
    )
    want = np.concatenate([np.var(acc, axis=-1).mean(0), mob.mean(0), com.mean(0), corr.mean(0)])
    np.testing.assert_allclose(td, want, rtol=1e-10)


def test_mean_force_and_gradient_match_numpy():
    force = RNG.uniform(0, 3, size=(7, 3, 750))
    assert features.mean_force(force) == pytest.approx(np.mean(force), rel=1e-14)
    t = RNG.normal(size=(4, 300)).cumsum(axis=1)
    np.testing.assert_allclose(
        features.temperature_gradient(t), np.gradient(t, axis=-1), rtol=1e-14, atol=1e-14
    )
    np.testing.assert_allclose(
        features.temperature_gradient(t.T, axis=0), np.gradient(t.T, axis=0), atol=1e-14
    )


def test_thermal_curve_is_mean_and_gradient():
    temp = 30 - np.cumsum(RNG.uniform(0, 0.01, size=(7, 1, 750)), axis=-1)
    curve = features.thermal_curve(temp)
    mean = temp.mean(axis=(0, 1))
    np.testing.assert_allclose(curve, np.concatenate([mean, np.gradient(mean)]), rtol=1e-13)


finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(x=hnp.arrays(np.float64, st.integers(8, 300), elements=finite), offset=st.floats(-1e4, 1e4))
def test_mobility_and_complexity_ignore_offsets(x, offset):
    a0, m0, c0 = features.hjorth(x)
    if not (a0 > 1e-6 and np.var(np.diff(x)) > 1e-6 and np.var(np.diff(x, 2)) > 1e-6):
        return  # degenerate signals have undefined ratios
    a1, m1, c1 = features.hjorth(x + offset)
    assert m1 == pytest.approx(m0, rel=1e-6)
    assert c1 == pytest.approx(c0, rel=1e-6)
    assert a1 == pytest.approx(a0, rel=1e-6, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(x=hnp.arrays(np.float64, st.integers(8, 200), elements=finite), scale=st.floats(1e-3, 1e3))
def test_scaling_scales_activity_only(x, scale):
    a0, m0, c0 = features.hjorth(x)
    if not (a0 > 1e-6 and np.var(np.diff(x)) > 1e-6 and np.var(np.diff(x, 2)) > 1e-6):
        return
    a1, m1, c1 = features.hjorth(x * scale)
    assert a1 == pytest.approx(a0 * scale**2, rel=1e-9)
    assert m1 == pytest.approx(m0, rel=1e-9)
    assert c1 == pytest.approx(c0, rel=1e-9)


def test_an_overflowing_hjorth_is_a_typed_error_not_nan():
    """Finite values whose squares or differences exceed float64: (nan, nan, nan) before."""
    from aptkt.errors import NonFiniteResultError

    with pytest.raises(NonFiniteResultError, match="x: the Hjorth"):
        features.hjorth([1e308, -1e308] * 10)
    with pytest.raises(NonFiniteResultError):
        features.hjorth(np.array([1e154, -1e154] * 10))  # the squares fit, the differences not
    with pytest.raises(NonFiniteResultError, match="acc"):
        features.texture_descriptor(np.tile([1e308, -1e308], (2, 3, 5)))
    with pytest.raises(NonFiniteResultError, match="force: the mean"):
        features.mean_force(np.array([1.7e308, 1.7e308]))
    # Undefined is not overflow: a constant signal still has NaN mobility and complexity.
    activity, mobility, complexity = features.hjorth([2.0] * 10)
    assert activity == 0.0 and np.isnan(mobility) and np.isnan(complexity)
