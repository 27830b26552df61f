"""EgoNet: the two-stream action-object network, its ablations and a CPU-fast variant.

Every variant is made by a *builder* function that decides sizes and composes
sub-modules (an RGB stream, an optional DHG stream, coordinate maps, a joint
head), after SAM's ``Sam``. Ablations are different builders, never flags
inside one class. ``streams`` holds the VGG stream, ``lite`` the CPU-fast
one, ``model`` the coordinate maps, the joint head and the models that fuse
streams, ``builders`` the builders, :data:`~egonet.network.builders.MODELS`
(variant names to builders) and ``build_model``, which looks them up::

    >>> import torch
    >>> from egonet.network.builders import build_model
    >>> model = build_model("egonet-lite")
    >>> rgb = torch.rand(1, 3, 57, 75)          # RGB in [0, 1]
    >>> dhg = torch.rand(1, 3, 57, 75)          # gray, height, depth in [0, 1]
    >>> model(rgb, dhg).shape                   # two-class logits at input size
    torch.Size([1, 2, 57, 75])
    >>> model.predict(rgb, dhg).shape           # action-object probability
    torch.Size([1, 57, 75])
    >>> model.predict(rgb, dhg, geometry="zoom8").shape  # the release's own output size
    torch.Size([1, 57, 73])
    >>> again = build_model(model.config.name, **model.config.options)

Conventions shared by every model (those of the authors' release, see
``shared/docs/egonet-reference.md``, "Released conventions"):

* Inputs are float tensors ``(N, 3, H, W)`` scaled to ``[0, 1]``, at any size
  with ``H, W >= 8``; the logits are resized to ``(H, W)`` exactly.
* ``rgb`` is in RGB order; ``dhg`` is a DHG image as the authors' files store
  it, read as RGB: channel 0 gray, 1 height, 2 depth (``dhg_order``
  ``"gray-height-depth"``). The VGG models feed the networks BGR and the
  flipped DHG (depth first), as the release does.
* The coordinate maps reach the joint head rows first, then columns
  (``coord_order`` ``"rows-first"``), as in the release, whose fc9 input
  channel 8192 is the row map.
* Normalisation constants are buffers inside the model (and so inside every
  ``state_dict``): callers never subtract means themselves.
* ``model(rgb, dhg)`` returns two-class logits ``(N, 2, H, W)`` (DeepLab-Obj:
  one per object class and background) and respects ``train()``/``eval()``;
  ``model.predict(rgb, dhg)`` returns one minus the background's softmax
  ``(N, H, W)`` (channel 1's for two classes) in eval mode under ``torch.no_grad``.
* ``model.config`` (a frozen ``ModelConfig``) holds the variant name and
  its architecture options, so a checkpoint can rebuild the model with
  ``build_model(config.name, **config.options)``. Checkpoints written before
  the two orders above were options lack them; ``saved_options`` gives
  those the orders they were trained with (columns first; DHG stored depth,
  height, gray).

Grid sizes of the faithful VGG stream (the released table, Caffe rounding):
pool1-3 (max 2x2, stride 2, pad 1, rounded up) map a side ``s`` to
``s // 2 + 1``; pool4 (max 2x2, stride 1, no pad) removes one row and one
column; conv5, pool5, fc6 and fc7 keep the size. A 481x641 frame therefore
gives a 60x80 fc7 grid (481 -> 241 -> 121 -> 61 -> 60). We keep pool4 unpadded
as the table says. The release zooms the grid x8 (Caffe's ``Interp``,
``zoom_factor`` 8: ``8 (h - 1) + 1`` rows, 473x633 from 60x80, 385x513 for a
386x514 frame); ``geometry="zoom8"`` gives exactly that. By default the
logits are resized to the input size instead (bilinear, corners aligned):
grid row ``i`` lands on image row ``i (H - 1) / (h - 1)`` where the release
puts it on row ``8 i`` of its shorter map, so the two differ by less than a
pixel over the frame (0.2 % of its height at 386 rows).
"""
