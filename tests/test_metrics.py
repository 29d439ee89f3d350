"""RMSD, r² and Sprague–Geers M, P against closed forms (openfdk.results.metrics)."""

import math

import numpy as np
import pytest

from openfdk.results.metrics import MetricsInputError, compare, r_squared, rmsd, sprague_geers


@pytest.fixture
def m():
    rng = np.random.default_rng(20170101)
    return rng.normal(0.0, 1.0, 250) + np.sin(np.linspace(0.0, 6.0, 250))


@pytest.mark.parametrize("k", [0.25, 1.0, 1.7, 3.0])
def test_scaled_signal(m, k):
    """c = k·m (k > 0): M = k − 1, P = 0, r² = 1, RMSD = |k − 1|·rms(m)."""
    c = k * m
    M, P = sprague_geers(c, m)
    assert M == pytest.approx(k - 1.0, abs=1e-12)
    assert P == pytest.approx(0.0, abs=1e-7)           # arccos(1 − ε) ~ √(2ε)
    assert r_squared(c, m) == pytest.approx(1.0, abs=1e-12)
    assert rmsd(c, m) == pytest.approx(abs(k - 1.0) * math.sqrt(np.mean(m ** 2)), rel=1e-12)


def test_opposite_signal_has_phase_one(m):
    """c = −m: cos = −1 → P = 1, same magnitude M = 0, r² = 1, RMSD = 2 rms(m)."""
    M, P = sprague_geers(-m, m)
    assert P == pytest.approx(1.0, abs=1e-7)
    assert M == pytest.approx(0.0, abs=1e-12)
    assert r_squared(-m, m) == pytest.approx(1.0, abs=1e-12)
    assert rmsd(-m, m) == pytest.approx(2.0 * math.sqrt(np.mean(m ** 2)), rel=1e-12)


@pytest.mark.parametrize("phi", [0.3, 1.0, math.pi / 2, 2.5])
def test_phase_shifted_sinusoids(phi):
    """Over whole periods (N uniform samples, endpoint excluded):
    Σ sin x sin(x+φ) = Σ ½[cos φ − cos(2x+φ)] = (N/2) cos φ and Σ sin² = N/2, so
    P = arccos(cos φ)/π = φ/π, M = 0, r² = cos²φ (both means vanish), and
    mean((sin(x+φ) − sin x)²) = ½ + ½ − cos φ → RMSD = √(1 − cos φ)."""
    x = np.linspace(0.0, 3 * 2 * np.pi, 300, endpoint=False)
    m, c = np.sin(x), np.sin(x + phi)
    M, P = sprague_geers(c, m)
    assert P == pytest.approx(phi / math.pi, abs=1e-9)
    assert M == pytest.approx(0.0, abs=1e-12)
    assert r_squared(c, m) == pytest.approx(math.cos(phi) ** 2, abs=1e-12)
    assert rmsd(c, m) == pytest.approx(math.sqrt(1.0 - math.cos(phi)), rel=1e-12)


def test_constant_offset(m):
    """c = m + b: RMSD = |b| exactly; the shape is identical, r² = 1."""
    b = -0.37
    assert rmsd(m + b, m) == pytest.approx(abs(b), rel=1e-12)
    assert r_squared(m + b, m) == pytest.approx(1.0, abs=1e-12)


def test_sprague_geers_of_an_offset_matches_the_sums():
    """m = 1 + sin x, c = m + 1 over whole periods: Σm² = N(1 + ½), Σc² = N(4 + ½),
    Σmc = N(2 + ½) → M = √(4.5/1.5) − 1 = √3 − 1, P = arccos(2.5/√(1.5·4.5))/π."""
    x = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    m = 1.0 + np.sin(x)
    M, P = sprague_geers(m + 1.0, m)
    assert M == pytest.approx(math.sqrt(3.0) - 1.0, rel=1e-12)
    assert P == pytest.approx(math.acos(2.5 / math.sqrt(1.5 * 4.5)) / math.pi, rel=1e-10)


def test_r_squared_matches_numpy_corrcoef():
    rng = np.random.default_rng(7)
    m = rng.normal(size=100)
    c = 0.6 * m + rng.normal(size=100)
    assert r_squared(c, m) == pytest.approx(np.corrcoef(c, m)[0, 1] ** 2, rel=1e-12)
    assert 0.1 < r_squared(c, m) < 0.9


def test_nan_pairs_are_dropped():
    """NaN in either series removes that pair; the metrics equal those of the rest."""
    x = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    m = np.sin(x) + 0.5
    c = 2.0 * m
    c_nan, m_nan = c.copy(), m.copy()
    c_nan[[3, 17]] = np.nan
    m_nan[[5, 17, 30]] = np.nan
    m_nan[8] = np.inf
    keep = np.ones(40, bool)
    keep[[3, 5, 8, 17, 30]] = False
    M, P = sprague_geers(c_nan, m_nan)
    assert M == pytest.approx(1.0, abs=1e-12)          # still c = 2m on the kept pairs
    assert P == pytest.approx(0.0, abs=1e-7)
    assert rmsd(c_nan, m_nan) == pytest.approx(math.sqrt(np.mean(m[keep] ** 2)), rel=1e-12)
    assert r_squared(c_nan, m_nan) == pytest.approx(1.0, abs=1e-12)
    # a different kept set changes the RMSD: the NaN rows really were skipped
    assert rmsd(c_nan, m_nan) != pytest.approx(math.sqrt(np.mean(m ** 2)), rel=1e-6)


def test_undefined_values_are_nan():
    m = np.linspace(0.0, 1.0, 10)
    const = np.full(10, 0.1)
    assert math.isnan(r_squared(const, m))             # constant computed series
    assert math.isnan(r_squared(m, const))             # constant measured series
    M, P = sprague_geers(m, np.zeros(10))              # no reference magnitude
    assert math.isnan(M) and math.isnan(P)
    M, P = sprague_geers(np.zeros(10), m)              # zero computed: M = −1, P undefined
    assert M == -1.0 and math.isnan(P)
    allnan = np.full(10, np.nan)
    result = compare(allnan, m)
    assert set(result) == {"rmsd", "r2", "M", "P"}
    assert all(math.isnan(v) for v in result.values())


def test_compare_collects_the_four_metrics(m):
    c = 1.2 * m + 0.1
    result = compare(c, m)
    M, P = sprague_geers(c, m)
    assert result == {"rmsd": rmsd(c, m), "r2": r_squared(c, m), "M": M, "P": P}


def test_bad_shapes_raise():
    with pytest.raises(MetricsInputError, match="10 samples but measured m has 9"):
        rmsd(np.zeros(10), np.zeros(9))
    with pytest.raises(ValueError, match="1-D"):
        compare(np.zeros((4, 3)), np.zeros((4, 3)))
