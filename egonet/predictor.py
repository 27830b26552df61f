"""Run a trained EgoNet model on numpy frames: uint8 in, float32 probabilities out.

:class:`NetworkPredictor` is the one way a trained model meets frames outside
training: the app's ``predict`` service (``flask egonet predict``, the queue's
``predict_frames`` job) goes through it. It sees a frame as training saw it:
resized to the training size ``(H, W)`` the way :class:`egonet.data.FrameDataset`
resizes (:func:`egonet.data.resize_frame`), and its probabilities are resized
back (bilinear, :func:`egonet.data.resize_probability`, which the training
loop's held-out maps use too) to the frame's own size. It satisfies the same
interface as the baselines in :mod:`egonet.baselines`: ``predict(rgb, dhg)``
returns an action-object probability map ``(H, W)``::

    >>> import numpy as np
    >>> from egonet.network.builders import build_model
    >>> from egonet.predictor import NetworkPredictor
    >>> predictor = NetworkPredictor(build_model("egonet-lite"), size=(24, 32))
    >>> rgb = np.zeros((57, 75, 3), np.uint8)
    >>> dhg = np.zeros((57, 75, 3), np.uint8)
    >>> probability = predictor.predict(rgb, dhg)
    >>> probability.shape, probability.dtype
    ((57, 75), dtype('float32'))

A checkpoint holds its training size: ``NetworkPredictor.from_checkpoint(state)``.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor

from egonet.checkpoint import model_from_checkpoint
from egonet.data import MIN_SIDE, check_size, resize_frame, resize_probability
from egonet.errors import EgonetError
from egonet.network.activations import stream_activations
from egonet.network.model import EgoNetModel

__all__ = ["NetworkPredictor"]


class NetworkPredictor:
    """Numpy in, numpy out at the original resolution, on the model's device.

    Args:
        model: A model from :func:`egonet.network.builders.build_model` (weights loaded).
        size: The training size ``(H, W)`` (``TrainConfig.size``): every frame
            is resized to it for the forward pass, as training resized it.
        device: Move the model there first (``"cpu"``, ``"cuda"``...). ``None``
            leaves it where it is; inputs always follow the model's device at
            call time, so moving the model later is fine.

    Raises:
        EgonetError: If ``model`` is not an :class:`~egonet.network.model.EgoNetModel`
            or ``size`` is not ``(H, W)`` with integers >= 8.
    """

    def __init__(
        self,
        model: EgoNetModel,
        *,
        size: tuple[int, int],
        device: str | torch.device | None = None,
    ) -> None:
        if not isinstance(model, EgoNetModel):
            raise EgonetError(
                f"model must be an EgoNetModel from egonet.network.builders.build_model, got {type(model).__name__}",
                field="model",
            )
        self.size = check_size(size)
        self.model = model if device is None else model.to(device)

    @classmethod
    def from_checkpoint(cls, state: Mapping, *, device: str | torch.device = "cpu") -> NetworkPredictor:
        """The checkpoint's model (eval mode, on ``device``) at the checkpoint's training size.

        Args:
            state: A checkpoint from :func:`egonet.checkpoint.load_checkpoint`.
            device: Where the model runs.
        """
        size = (state["config"]["height"], state["config"]["width"])
        return cls(model_from_checkpoint(state, device=device), size=size)

    @property
    def device(self) -> torch.device:
        """Where the model's weights are now."""
        return next(self.model.parameters()).device

    @torch.no_grad()
    def predict(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> np.ndarray:
        """Action-object probability of every pixel.

        Args:
            rgb: ``(H, W, 3)`` uint8 RGB frame, ``H, W >= 8``.
            dhg: ``(H, W, 3)`` uint8 DHG image of the same frame, channels as
                the authors' files and our media store them (gray, height,
                depth: ``egonet.io.read_dhg``); may be ``None`` for models that
                do not read DHG.

        Returns:
            ``(H, W)`` float32 probabilities in ``[0, 1]`` (no gradients; the
            model's mode is left as it is, eval after ``from_checkpoint``).

        Raises:
            EgonetError: If an input is not a uint8 ``(H, W, 3)`` array, the two
                sizes differ, or ``dhg`` is missing for a model that needs it.
        """
        _check_frame(rgb, "rgb")
        if dhg is not None:
            _check_frame(dhg, "dhg")
            if dhg.shape != rgb.shape:
                raise EgonetError(
                    f"dhg must have the shape of rgb {rgb.shape}, got {dhg.shape}: "
                    "both must come from the same frame",
                    field="dhg",
                )
        elif self.model.uses_dhg:
            raise EgonetError(
                f"dhg is required by {self.model.config.name!r}: pass the frame's (H, W, 3) uint8 DHG image",
                field="dhg",
            )
        x_dhg = self._to_tensor(dhg) if dhg is not None else None
        probability = self.model.predict(self._to_tensor(rgb), x_dhg)[0]  # (h, w) at the training size
        return resize_probability(probability.float().cpu().numpy(), rgb.shape[:2])

    @torch.no_grad()
    def activations(self, rgb: np.ndarray, dhg: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Each pathway's fc7 averaged over channels, upsampled to the frame: the paper's Figure 3.

        The frame is resized to the training size as for :meth:`predict`;
        each map (:func:`egonet.network.activations.stream_activations`) is
        upsampled from the network's grid to the frame bilinearly, corners
        aligned (as the network's own output is).

        Args:
            rgb: ``(H, W, 3)`` uint8 RGB frame.
            dhg: ``(H, W, 3)`` uint8 DHG image of the same frame, or ``None``
                (then only the RGB pathway runs).

        Returns:
            ``{pathway: (H, W) float32}``, pathways ``rgb``/``dhg`` or ``joint``
            (mean activations, >= 0, unbounded).

        Raises:
            EgonetError: As :meth:`predict`, but ``dhg`` may be missing when the model has an RGB stream.
        """
        _check_frame(rgb, "rgb")
        if dhg is not None:
            _check_frame(dhg, "dhg")
            if dhg.shape != rgb.shape:
                raise EgonetError(f"dhg must have the shape of rgb {rgb.shape}, got {dhg.shape}", field="dhg")
        maps = stream_activations(self.model, self._to_tensor(rgb), self._to_tensor(dhg) if dhg is not None else None)
        size = rgb.shape[:2]
        return {name: F.interpolate(m[:, None].float(), size=size, mode="bilinear", align_corners=True)[0, 0].cpu().numpy()
                for name, m in maps.items()}

    def _to_tensor(self, frame: np.ndarray) -> Tensor:
        """uint8 ``(H, W, 3)`` -> ``(1, 3, h, w)`` in ``[0, 1]`` at the training size, on the model's device."""
        parameter = next(self.model.parameters())
        # A copy: torch.from_numpy refuses read-only arrays and would share memory otherwise.
        x = torch.from_numpy(np.array(resize_frame(frame, self.size).transpose(2, 0, 1), order="C"))
        return x[None].to(parameter.device, parameter.dtype).div_(255.0)


def _check_frame(frame: object, name: str) -> None:
    if not isinstance(frame, np.ndarray):
        raise EgonetError(f"{name} must be a numpy array (H, W, 3) of uint8, got {type(frame).__name__}", field=name)
    if frame.dtype != np.uint8:
        raise EgonetError(
            f"{name} must be uint8 (H, W, 3), got dtype {frame.dtype}: convert 8-bit images, "
            "e.g. (x * 255).round().astype(np.uint8) for floats in [0, 1]",
            field=name,
        )
    if frame.ndim != 3 or frame.shape[2] != 3:
        raise EgonetError(f"{name} must have shape (H, W, 3), got {frame.shape}", field=name)
    if min(frame.shape[:2]) < MIN_SIDE:
        raise EgonetError(
            f"{name} must be at least {MIN_SIDE}x{MIN_SIDE} pixels, got {frame.shape[:2]}", field=name
        )
