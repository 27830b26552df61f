"""Run a trained EgoNet model on numpy frames: uint8 in, float32 probabilities out.

:class:`NetworkPredictor` sits between a model from :mod:`egonet.network` and
its callers (services, scoring, the CLI). It satisfies the same interface as
the baselines in :mod:`egonet.baselines`: ``predict(rgb, dhg)`` returns an
action-object probability map ``(H, W)`` at the frame's own resolution::

    >>> import numpy as np
    >>> from egonet.network import build_model
    >>> from egonet.predictor import NetworkPredictor
    >>> predictor = NetworkPredictor(build_model("egonet-lite"), max_side=320)
    >>> rgb = np.zeros((57, 75, 3), np.uint8)
    >>> dhg = np.zeros((57, 75, 3), np.uint8)
    >>> probability = predictor.predict(rgb, dhg)
    >>> probability.shape, probability.dtype
    ((57, 75), dtype('float32'))
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from egonet.network import MIN_SIDE, EgoNetModel

__all__ = ["NetworkPredictor"]


class NetworkPredictor:
    """Numpy in, numpy out at the original resolution, on the model's device.

    Args:
        model: A model from :func:`egonet.network.build_model` (weights loaded).
        device: Move the model there first (``"cpu"``, ``"cuda"``...). ``None``
            leaves it where it is; inputs always follow the model's device at
            call time, so moving the model later is fine.
        max_side: When a frame's longer side exceeds this, the frame is
            downscaled (antialiased bilinear) to that longer side before the
            forward pass and the probabilities are upsampled (bilinear) back
            to the frame size. ``None`` always runs at full resolution.

    Raises:
        ValueError: If ``model`` is not an :class:`~egonet.network.EgoNetModel`
            or ``max_side`` is not an integer >= 8.
    """

    def __init__(
        self,
        model: EgoNetModel,
        *,
        device: str | torch.device | None = None,
        max_side: int | None = None,
    ) -> None:
        if not isinstance(model, EgoNetModel):
            raise ValueError(
                f"model must be an EgoNetModel from egonet.network.build_model, got {type(model).__name__}"
            )
        if max_side is not None and (
            isinstance(max_side, bool) or not isinstance(max_side, int) or max_side < MIN_SIDE
        ):
            raise ValueError(f"max_side must be None or an integer >= {MIN_SIDE}, got {max_side!r}")
        self.model = model if device is None else model.to(device)
        self.max_side = max_side

    @property
    def device(self) -> torch.device:
        """Where the model's weights are now."""
        return next(self.model.parameters()).device

    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Action-object probability of every pixel.

        Args:
            rgb: ``(H, W, 3)`` uint8 RGB frame, ``H, W >= 8``.
            dhg: ``(H, W, 3)`` uint8 DHG image (depth, height, grey) of the same
                frame; may be ``None`` for models that do not read DHG.

        Returns:
            ``(H, W)`` float32 probabilities in ``[0, 1]`` (eval mode, no gradients).

        Raises:
            ValueError: If an input is not a uint8 ``(H, W, 3)`` array, the two
                sizes differ, or ``dhg`` is missing for a model that needs it.
        """
        _check_frame(rgb, "rgb")
        height, width = rgb.shape[:2]
        if dhg is not None:
            _check_frame(dhg, "dhg")
            if dhg.shape != rgb.shape:
                raise ValueError(
                    f"dhg must have the shape of rgb {rgb.shape}, got {dhg.shape}: "
                    "both must come from the same frame"
                )
        elif self.model.uses_dhg:
            raise ValueError(
                f"dhg is required by {self.model.config.name!r}: pass the frame's (H, W, 3) uint8 DHG image"
            )

        size = self._forward_size(height, width)
        x_rgb = self._to_tensor(rgb, size)
        x_dhg = self._to_tensor(dhg, size) if dhg is not None and self.model.uses_dhg else None
        probability = self.model.predict(x_rgb, x_dhg)  # (1, h, w)
        if size != (height, width):
            probability = F.interpolate(
                probability[:, None], size=(height, width), mode="bilinear", align_corners=False
            )[:, 0]
        probability = probability[0].clamp_(0.0, 1.0)
        return probability.to("cpu", torch.float32).numpy()

    def _forward_size(self, height: int, width: int) -> tuple[int, int]:
        """The (h, w) the network sees: the frame size, or scaled so max(h, w) == max_side."""
        longest = max(height, width)
        if self.max_side is None or longest <= self.max_side:
            return height, width
        scale = self.max_side / longest
        return max(MIN_SIDE, round(height * scale)), max(MIN_SIDE, round(width * scale))

    def _to_tensor(self, frame: np.ndarray, size: tuple[int, int]) -> Tensor:
        """uint8 ``(H, W, 3)`` -> float ``(1, 3, h, w)`` in ``[0, 1]`` on the model's device."""
        parameter = next(self.model.parameters())
        # Copy: torch.from_numpy refuses read-only arrays and would share memory otherwise.
        x = torch.from_numpy(np.array(frame, copy=True)).to(parameter.device)
        x = x.permute(2, 0, 1)[None].to(parameter.dtype).div_(255.0)
        if tuple(x.shape[-2:]) != size:
            x = F.interpolate(x, size=size, mode="bilinear", align_corners=False, antialias=True)
            x = x.clamp_(0.0, 1.0)
        return x


def _check_frame(frame: object, name: str) -> None:
    if not isinstance(frame, np.ndarray):
        raise ValueError(f"{name} must be a numpy array (H, W, 3) of uint8, got {type(frame).__name__}")
    if frame.dtype != np.uint8:
        raise ValueError(
            f"{name} must be uint8 (H, W, 3), got dtype {frame.dtype}: convert 8-bit images, "
            "e.g. (x * 255).round().astype(np.uint8) for floats in [0, 1]"
        )
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"{name} must have shape (H, W, 3), got {frame.shape}")
    if min(frame.shape[:2]) < MIN_SIDE:
        raise ValueError(f"{name} must be at least {MIN_SIDE}x{MIN_SIDE} pixels, got {frame.shape[:2]}")
