"""The baselines that learn nothing: a centre prior and spectral-residual saliency.

Neither is a row of the paper's Table 2; both are cheap references that
bound what "no learning" scores on a dataset (a centre bias, bottom-up
saliency).
"""

from __future__ import annotations

import cv2
import numpy as np

from egonet.errors import EgonetError
from egonet.saliency import check_frame as _check_frame

__all__ = ["CenterPrior", "SpectralResidualSaliency", "check_positive"]


def check_positive(value: float, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise EgonetError(f"{name} must be a positive number, got {value!r}", field=name)
    if not np.isfinite(value) or value <= 0:
        raise EgonetError(f"{name} must be a positive finite number, got {value}", field=name)
    return float(value)



class CenterPrior:
    """An isotropic Gaussian centred on the image, peak 1.

    ``p(x, y) = exp(-d^2 / (2 s^2))`` where ``d`` is the distance in pixels to
    the image centre ``((W - 1) / 2, (H - 1) / 2)`` and ``s = sigma *
    sqrt(H^2 + W^2)``: ``sigma`` is a fraction of the image **diagonal**, so
    the prior is round in pixels and scales with the frame.

    Args:
        sigma: Standard deviation as a fraction of the image diagonal, > 0.

    Raises:
        ValueError: If ``sigma`` is not positive.

    Example:
        >>> p = CenterPrior(sigma=0.25).predict(np.zeros((3, 3, 3), np.uint8), None)
        >>> float(p[1, 1])
        1.0
    """

    name, version = "centre prior", 1

    def __init__(self, *, sigma: float = 0.25) -> None:
        self.sigma = check_positive(sigma, "sigma")

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Return the centre prior at the frame's size, float32 (H, W).

        Args:
            rgb: Colour frame, uint8 (H, W, 3); only its size is used.
            dhg: Ignored; may be None.

        Returns:
            Values in (0, 1], float32 (H, W), largest at the centre.
        """
        h, w = _check_frame(rgb, dhg)
        s = self.sigma * float(np.hypot(h, w))
        gy = np.exp(-((np.arange(h) - (h - 1) / 2.0) ** 2) / (2 * s * s)).astype(np.float32)
        gx = np.exp(-((np.arange(w) - (w - 1) / 2.0) ** 2) / (2 * s * s)).astype(np.float32)
        return np.outer(gy, gx)


class SpectralResidualSaliency:
    """Spectral-residual saliency (Hou & Zhang, CVPR 2007).

    The frame is converted to grayscale and downscaled (area interpolation)
    to ``width`` pixels wide, keeping its aspect ratio. With ``F`` its
    Fourier transform, ``L = log |F|`` and ``P`` its phase, the spectral
    residual is ``R = L - mean3x3(L)`` and the saliency is
    ``|IFFT(exp(R + iP))|^2``, smoothed with a Gaussian of ``blur_sigma``
    (in downscaled pixels). The map is then min-max normalised to [0, 1]
    per image and resized bilinearly to the frame. Normalising is part of
    how this baseline is defined (saliency has no probabilistic scale);
    a uniform frame (or one whose saliency is constant) gives zeros.

    Args:
        width: Width of the working image in pixels (the paper uses 64).
        blur_sigma: Standard deviation of the final smoothing, in working
            pixels, > 0.

    Raises:
        ValueError: If ``width`` < 8 or ``blur_sigma`` is not positive.
    """

    name, version = "saliency", 1

    def __init__(self, *, width: int = 64, blur_sigma: float = 2.5) -> None:
        if isinstance(width, bool) or not isinstance(width, (int, np.integer)) or width < 8:
            raise EgonetError(f"width must be an int >= 8, got {width!r}", field="width")
        self.width = int(width)
        self.blur_sigma = check_positive(blur_sigma, "blur_sigma")

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Return the normalised saliency map, float32 (H, W) in [0, 1].

        Args:
            rgb: Colour frame, uint8 (H, W, 3).
            dhg: Ignored; may be None.

        Returns:
            Saliency in [0, 1], float32 (H, W).
        """
        h, w = _check_frame(rgb, dhg)
        gray = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY).astype(np.float32)
        ww = min(self.width, w)
        wh = max(1, round(h * ww / w))
        small = cv2.resize(gray, (ww, wh), interpolation=cv2.INTER_AREA) / 255.0
        if float(small.max() - small.min()) < 1e-6:
            # A uniform frame has no residual, only rounding noise: say so.
            return np.zeros((h, w), dtype=np.float32)
        spectrum = np.fft.fft2(small)
        log_amp = np.log(np.abs(spectrum) + 1e-8)
        phase = np.angle(spectrum)
        residual = log_amp - cv2.blur(log_amp, (3, 3), borderType=cv2.BORDER_REFLECT)
        sal = np.abs(np.fft.ifft2(np.exp(residual + 1j * phase))) ** 2
        sal = cv2.GaussianBlur(sal.astype(np.float32), (0, 0), self.blur_sigma, borderType=cv2.BORDER_REFLECT)
        lo, hi = float(sal.min()), float(sal.max())
        if not hi - lo > 1e-6 * hi:
            return np.zeros((h, w), dtype=np.float32)
        sal = (sal - lo) / (hi - lo)
        out = cv2.resize(sal, (w, h), interpolation=cv2.INTER_LINEAR)
        return np.clip(out, 0.0, 1.0, out=out).astype(np.float32, copy=False)
