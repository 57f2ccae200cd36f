"""lidarjax.turbulence: the dependency-free FFT Mann generator against the spectral
model of lidarjax.spectral (same tensor, same box covariance)."""

import numpy as np
import pytest

from lidarjax.turbulence import _amplitude, box_variance, fft_mann_box, mann_tensor


@pytest.mark.parametrize("gamma", [0.0, 3.9])
def test_amplitude_is_a_square_root_of_the_mann_tensor(gamma):
    """C C^H = Phi at random wavenumbers and on the k1 = 0 and k1 = k2 = 0 axes (the limits
    of Mann's zeta_1 there)."""
    rng = np.random.default_rng(0)
    k = np.concatenate([rng.standard_normal((200, 3)) * 0.1,
                        [[0.0, 0.05, 0.02], [0.0, 0.0, 0.03], [0.05, 0.0, 0.0], [0.0, -0.2, 0.0]]])
    c = _amplitude(k[:, 0], k[:, 1], k[:, 2], 1.3, 30.0, gamma)
    phi = c @ np.conj(np.swapaxes(c, -1, -2))
    ref = mann_tensor(k, 1.3, 30.0, gamma)
    np.testing.assert_allclose(phi, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_box_covariance_matches_the_spectral_model():
    """The drawn boxes' covariance, averaged over seeds, equals sum_k Phi(k) dk over the
    box's wavenumbers (`lidarjax.turbulence.box_variance`) within 4.5 standard errors."""
    shape, spacing = (16, 8, 8), (8.0, 8.0, 8.0)
    covs = np.array([np.cov(fft_mann_box(shape, spacing, seed=s).reshape(-1, 3).T, bias=True)
                     for s in range(60)])
    ref = box_variance(shape, spacing, 1.0, 30.0, 3.9)
    err = covs.std(axis=0) / np.sqrt(covs.shape[0])
    for i, j in ((0, 0), (1, 1), (2, 2), (0, 2)):
        assert abs(covs[:, i, j].mean() - ref[i, j]) < 4.5 * err[i, j], (i, j)
    box = fft_mann_box(shape, spacing, sigma_u=1.5, seed=3)
    assert box.shape == shape + (3,)
    np.testing.assert_allclose(box[..., 0].std(), 1.5)
    with pytest.raises(ValueError, match="spacing"):
        fft_mann_box(shape, (1.0, 0.0, 1.0))
