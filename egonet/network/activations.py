"""What each pathway sees: its last feature map averaged over channels, as the paper's Figure 3.

The paper's Figure 3 shows "the fc7 activations of the RGB and DHG
pathways, averaged over all channels" beside the two inputs. Every stream
of every variant ends in its fc7 (a 1x1 convolution, ReLU and dropout; the
release's layers ``fc7`` and ``dhg_fc7``; the lite variant's 1x1 projection
of the same name, the last feature map of its stream), so a forward hook on
the stream catches fc7 after its ReLU (dropout is off in eval mode), on the
network's grid (stride 8). :func:`stream_activations` returns the mean over
channels there; ``NetworkPredictor.activations`` upsamples it to the frame.

Example:
    >>> import torch
    >>> from egonet.network.builders import build_model
    >>> model = build_model("egonet-lite")
    >>> maps = stream_activations(model, torch.rand(1, 3, 40, 48), torch.rand(1, 3, 40, 48))
    >>> {name: tuple(m.shape) for name, m in maps.items()}
    {'rgb': (1, 5, 6), 'dhg': (1, 5, 6)}
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from egonet.errors import EgonetError
from egonet.network.model import EgoNetModel, _check_input

__all__ = ["LAYERS", "pathways", "stream_activations"]

LAYERS = {"rgb": "fc7", "dhg": "dhg_fc7", "joint": "fc7"}
"""Each pathway's layer, by the release's names (``joint``: the single-stream ablation's one stream)."""

_STREAMS = (("rgb", "rgb_stream"), ("dhg", "dhg_stream"), ("joint", "stream"))


def pathways(model: EgoNetModel) -> dict[str, nn.Module]:
    """The model's streams by pathway: ``rgb`` and ``dhg`` (two-stream variants, those present), or ``joint``."""
    if not isinstance(model, EgoNetModel):
        raise EgonetError(f"model must be an EgoNetModel from build_model, got {type(model).__name__}", field="model")
    return {name: module for name, attr in _STREAMS if isinstance(module := getattr(model, attr, None), nn.Module)}


def stream_activations(model: EgoNetModel, rgb: Tensor, dhg: Tensor | None = None) -> dict[str, Tensor]:
    """Each pathway's fc7 (after ReLU) averaged over its channels, on the network's grid.

    Runs the model in eval mode without gradients (its mode is restored).
    Without ``dhg`` a model that reads DHG runs its RGB stream alone (the
    DHG pathway is then left out: it cannot run); a model with no pathway
    that can run without DHG raises.

    Args:
        model: A model from :func:`egonet.network.builders.build_model`.
        rgb: ``(N, 3, H, W)`` float RGB in ``[0, 1]``.
        dhg: ``(N, 3, H, W)`` float DHG (gray, height, depth) in ``[0, 1]``, or ``None``.

    Returns:
        ``{pathway: (N, h, w)}`` for ``rgb``/``dhg`` (the streams the model
        has) or ``joint``, float, on the model's device.

    Raises:
        EgonetError: a bad input, or no pathway that can run without DHG.
    """
    streams = pathways(model)
    _check_input(rgb, "rgb")
    if dhg is None and model.uses_dhg and "rgb" not in streams:
        raise EgonetError(f"dhg is required by {model.config.name!r}: none of its pathways reads RGB alone", field="dhg")
    captured: dict[str, Tensor] = {}

    def keep(name: str):
        return lambda module, inputs, output: captured.__setitem__(name, output.mean(dim=1))

    hooks = [module.register_forward_hook(keep(name)) for name, module in streams.items()]
    was_training = model.training
    model.eval()
    try:
        with torch.no_grad():
            if dhg is None and model.uses_dhg:
                model.rgb_stream(model.rgb_norm(rgb))  # the RGB stream as the full forward runs it
            else:
                model(rgb, dhg)
    finally:
        model.train(was_training)
        for hook in hooks:
            hook.remove()
    return captured
