"""The analytic lidar–rotor spectra against the time domain: the REWS and its lidar estimate
simulated in Kaimal/IEC turbulence (frozen, Veers' method) and processed sample by sample.
Welch's coherence lies in its 95 % band about the analytic one in every bin up to the
bandwidth, and the simulated spectra are the analytic ones (the hour-long runs are in
benchmarks/lac_time_domain.py)."""

import numpy as np
import pytest
from scipy import stats

from lidarjax import control as lc

DT, NPERSEG, DURATION = 1.0, 128, 30 * 128.0  # 64 min: 30 Welch segments, each bin 30 lines of the record


@pytest.fixture(scope="module")
def run():
    rotor = lc.rotor_disc(63.0, spacing=10.5)  # the NREL 5 MW, 113 points
    focus = lc.cone_points(100.0, 20.0, 4, azimuth_offset=45.0)
    samples = lc.lidar_samples(focus, offsets=np.linspace(-30, 30, 5), offset_weights=[1, 2, 3, 2, 1],
                               times=[0.25, 0.5, 0.75, 1.0])
    inflow = lc.KaimalInflow(12.0, 0.16)
    t, rews, est = lc.kaimal_rews_series(samples, rotor, inflow, duration=DURATION, dt=DT, seed=0)
    lines = np.arange(1, t.size // 2) / DURATION  # the record's frequencies: the analytic model on them
    spectra = lc.lac_spectra(samples, rotor, inflow, lines)
    lead = float(np.sum(samples.weights * (samples.points[:, 0] / 12.0 - samples.delays)))
    return rews, est, spectra, lead, samples, rotor


def test_welch_coherence_within_its_band_up_to_the_bandwidth(run):
    rews, est, spectra, lead = run[:4]
    f_b = float(lc.coherence_bandwidth(spectra)[0])
    f, c, n = lc.welch_coherence(rews, est, DT, nperseg=NPERSEG, lead=lead)
    sel = f <= f_b
    k = np.rint(f[sel] * DURATION).astype(int) - 1  # the Welch bins are lines of the record
    np.testing.assert_allclose(np.asarray(spectra.frequency)[k], f[sel], rtol=1e-12)
    g2 = np.asarray(spectra.coherence)[k]
    lo, hi = lc.coherence_band(g2, n, n_bins=int(sel.sum()))  # simultaneous 95 % over the bins
    assert n == 30 and sel.sum() >= 7 and 0.04 < f_b < 0.08
    assert np.all((lo <= c[sel]) & (c[sel] <= hi)), (c[sel], g2)
    # the check can fail: the model with twice the simulated coherence decay (24, not 12) does
    samples, rotor = run[4:]
    other = lc.lac_spectra(samples, rotor, lc.KaimalInflow(12.0, 0.16, coherence_decay=24.0),
                           np.asarray(spectra.frequency))  # the same shapes: the same compiled program
    lo, hi = lc.coherence_band(np.asarray(other.coherence)[k], n, n_bins=int(sel.sum()))
    assert not np.all((lo <= c[sel]) & (c[sel] <= hi))


def test_simulated_spectra_are_the_analytic_ones(run):
    """The record's periodogram averaged over bands of 30 lines against the analytic spectra
    averaged likewise: chi-square with 60 degrees of freedom (simultaneous 99 % over the bands)."""
    rews, est, spectra = run[:3]
    n = rews.size
    for x, s in ((rews, spectra.S_RR), (est, spectra.S_LL)):
        p = 2 * np.abs(np.fft.rfft(x)[1:n // 2]) ** 2 * DT / n  # one-sided periodogram, (m/s)^2/Hz
        m = 30 * (p.size // 30)
        band = p[:m].reshape(-1, 30).mean(1) / np.asarray(s)[:m].reshape(-1, 30).mean(1)
        q = 0.01 / (2 * band.size)
        lo, hi = stats.chi2.ppf([q, 1 - q], 60) / 60
        assert np.all((lo < band) & (band < hi)), band
    cross = np.mean(rews * est) / np.sqrt(np.mean(rews**2) * np.mean(est**2))
    assert cross > 0.5
