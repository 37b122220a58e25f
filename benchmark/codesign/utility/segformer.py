"""SegFormer (Xie et al. 2021) semantic-segmentation utility model, built and loaded offline.

The network is Hugging Face ``transformers``' ``SegformerForSemanticSegmentation`` built from a
``SegformerConfig`` with random weights; weights come only from local files
(:func:`load_segformer_weights`), never from the Hub. The offline switches are set before
``transformers`` is imported so that nothing in it tries the network either.
"""

from __future__ import annotations

import re

import common.offline  # noqa: F401  (before transformers: nothing in it tries the network)

from collections.abc import Callable, Mapping  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402
from transformers import SegformerConfig, SegformerForSemanticSegmentation  # noqa: E402
from transformers.models.segformer.modeling_segformer import SegformerDecodeHead  # noqa: E402

from benchmark.codesign.utility.bilinear import resize_bilinear, resize_for_training  # noqa: E402

__all__ = [
    "IMAGENET_MEAN",
    "IMAGENET_STD",
    "VARIANTS",
    "build_segformer",
    "load_segformer_weights",
    "segment_logits",
    "sliding_window_logits",
]

# Mix-Transformer encoder sizes (all with depths [2, 2, 2, 2], sr_ratios [8, 4, 2, 1]).
# b0 and b1 are the published MiT-B0 / MiT-B1; b0-narrow halves every width of b0 for quick CPU
# runs; tiny quarters them, for smoke tests.
VARIANTS: dict[str, dict[str, list[int] | int]] = {
    "b0": dict(hidden_sizes=[32, 64, 160, 256], num_attention_heads=[1, 2, 5, 8], decoder_hidden_size=256),
    "b1": dict(hidden_sizes=[64, 128, 320, 512], num_attention_heads=[1, 2, 5, 8], decoder_hidden_size=256),
    "b0-narrow": dict(hidden_sizes=[16, 32, 80, 128], num_attention_heads=[1, 1, 2, 4], decoder_hidden_size=128),
    "tiny": dict(hidden_sizes=[8, 16, 40, 64], num_attention_heads=[1, 1, 1, 2], decoder_hidden_size=64),
}

# SegFormer's encoders were pretrained on ImageNet with this normalisation (RGB, [0, 1] scale).
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)


class TrainingDecodeHead(SegformerDecodeHead):
    """SegFormer's all-MLP decode head, its four resizes done by `resize_bilinear` when a gradient
    flows (matrix products, the first stage not resized), else exactly ``transformers``' forward.

    The same weights and submodules as ``SegformerDecodeHead`` (`build_segformer` swaps the class of
    the head it built, so initialisation and the random stream are untouched); the values equal the
    original's up to float rounding (tests/benchmark/codesign/test_bilinear.py), and inference, run without a
    gradient, is the original to the bit.
    """

    def forward(self, encoder_hidden_states: torch.Tensor, **kwargs: object) -> torch.Tensor:
        if not (torch.is_grad_enabled() and any(h.requires_grad for h in encoder_hidden_states)) or (
                self.config.reshape_last_stage is False):
            return super().forward(encoder_hidden_states, **kwargs)
        batch_size = encoder_hidden_states[-1].shape[0]
        size = encoder_hidden_states[0].shape[2:]
        stages = []
        for state, linear_proj in zip(encoder_hidden_states, self.linear_projections):
            height, width = state.shape[2], state.shape[3]
            state = linear_proj(state).transpose(1, 2).reshape(batch_size, -1, height, width)
            stages.append(resize_bilinear(state, size))
        hidden = self.linear_fuse(torch.cat(stages[::-1], dim=1))
        hidden = self.dropout(self.activation(self.batch_norm(hidden)))
        return self.classifier(hidden)


def build_segformer(variant: str = "b0", num_labels: int = 19) -> SegformerForSemanticSegmentation:
    """Build a randomly initialised SegFormer without touching the network.

    Args:
        variant: one of :data:`VARIANTS` (``"b0"``, ``"b1"``, ``"b0-narrow"``, ``"tiny"``).
        num_labels: output classes (19 for Cityscapes' train ids).

    Returns:
        The model in training mode, on the CPU. Its ``logits`` are at 1/4 of the input size;
        use :func:`segment_logits` for full-size logits.
    """
    if variant not in VARIANTS:
        raise ValueError(f"unknown SegFormer variant {variant!r}; valid: {sorted(VARIANTS)}")
    config = SegformerConfig(
        num_labels=num_labels,
        depths=[2, 2, 2, 2],
        sr_ratios=[8, 4, 2, 1],
        semantic_loss_ignore_index=255,
        **VARIANTS[variant],
    )
    model = SegformerForSemanticSegmentation(config)
    model.decode_head.__class__ = TrainingDecodeHead  # the same module, a faster backward (see the class)
    return model


def _read_state_dict(path: Path) -> Mapping[str, torch.Tensor]:
    if path.is_dir():
        # Only an existing local directory reaches from_pretrained; local_files_only forbids the Hub.
        return SegformerForSemanticSegmentation.from_pretrained(str(path), local_files_only=True).state_dict()
    if path.suffix == ".safetensors":
        from safetensors.torch import load_file

        return load_file(str(path), device="cpu")
    if path.suffix in {".bin", ".pth", ".pt"}:
        # weights_only=True: never unpickle arbitrary objects from a downloaded file.
        raw = torch.load(path, map_location="cpu", weights_only=True)
        for wrapper in ("state_dict", "model"):
            if isinstance(raw, Mapping) and isinstance(raw.get(wrapper), Mapping):
                return raw[wrapper]
        return raw
    raise ValueError(
        f"SegFormer weights {path}: unsupported file type {path.suffix!r}; "
        "give a .safetensors, .bin/.pth/.pt state dict, or a directory written by save_pretrained"
    )


# Published SegFormer checkpoints (e.g. nvidia/segformer-b0-finetuned-cityscapes-1024-1024) use
# the parameter names of transformers < 5; transformers 5 renamed the modules and converts names
# only inside from_pretrained. These renames (from transformers' conversion_mapping) do the same
# for plain state-dict files. They are tried only on keys the model does not know, so files and
# models of either naming load.
_LEGACY_RENAMES: list[tuple[str, str]] = [
    (r"encoder\.patch_embeddings\.(\d+)\.", r"stages.\1.patch_embeddings."),
    (r"encoder\.block\.(\d+)\.", r"stages.\1.blocks."),
    (r"encoder\.layer_norm\.(\d+)\.", r"stages.\1.layer_norm."),
    (r"attention\.self\.query\.", "attention.q_proj."),
    (r"attention\.self\.key\.", "attention.k_proj."),
    (r"attention\.self\.value\.", "attention.v_proj."),
    (r"attention\.self\.sr\.", "attention.sequence_reduction.sequence_reduction."),
    (r"attention\.self\.layer_norm\.", "attention.sequence_reduction.layer_norm."),
    (r"attention\.output\.dense\.", "attention.o_proj."),
    (r"mlp\.dense1\.", "mlp.fc1."),
    (r"mlp\.dense2\.", "mlp.fc2."),
    (r"layer_norm_1\.", "layernorm_before."),
    (r"layer_norm_2\.", "layernorm_after."),
    (r"decode_head\.linear_c\.", "decode_head.linear_projections."),
]


def _legacy_to_current(key: str) -> str:
    for pattern, replacement in _LEGACY_RENAMES:
        key = re.sub(pattern, replacement, key)
    return key


def _normalise_keys(state: Mapping[str, torch.Tensor], known: set[str]) -> dict[str, torch.Tensor]:
    """Map checkpoint names onto the model's (``known``) names where a match exists.

    Tried in order: the name as is, without a ``module.`` (DataParallel) prefix, with the
    transformers < 5 names converted, and with a ``segformer.`` prefix added (a bare encoder as
    saved by ``SegformerModel``). A name that matches nothing is kept and reported as unexpected.
    """
    out = {}
    for key, value in state.items():
        bare = key.removeprefix("module.")
        candidates = [bare, _legacy_to_current(bare), "segformer." + bare, _legacy_to_current("segformer." + bare)]
        out[next((c for c in candidates if c in known), key)] = value
    return out


def load_segformer_weights(
    model: SegformerForSemanticSegmentation, path: str | Path, strict: bool = True
) -> SegformerForSemanticSegmentation:
    """Load local weights into ``model`` (in place) and return it.

    Args:
        model: a model from :func:`build_segformer` of the checkpoint's variant.
        path: a ``.safetensors`` file, a ``.bin``/``.pth``/``.pt`` state dict (optionally
            wrapped as ``{"state_dict": ...}``), or an existing directory written by
            ``save_pretrained``. Hub names are refused: nothing is ever downloaded. Names of
            either transformers generation (< 5 or >= 5) are accepted.
        strict: if False, keys missing from the file keep their current values and extra keys
            are ignored (e.g. an ImageNet encoder without a decode head); at least one tensor
            must still match.

    Raises:
        FileNotFoundError: ``path`` is not an existing local file or directory.
        ValueError: unsupported file type, missing/unexpected keys (with ``strict``), no
            matching key at all, or tensors of the wrong shape.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(
            f"SegFormer weights {path} do not exist; give a local file or save_pretrained directory "
            "(Hub model names are not downloaded)"
        )
    expected = model.state_dict()
    state = _normalise_keys(_read_state_dict(path), set(expected))
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    if strict and (missing or unexpected):
        raise ValueError(
            f"SegFormer weights {path} do not match the model: {len(missing)} missing keys {missing[:10]}, "
            f"{len(unexpected)} unexpected keys {unexpected[:10]}; check the variant and num_labels"
        )
    matched = {k: v for k, v in state.items() if k in expected}
    if not matched:
        raise ValueError(f"SegFormer weights {path} share no key with the model, e.g. file keys {sorted(state)[:5]}")
    wrong_shape = [f"{k}: file {tuple(v.shape)} vs model {tuple(expected[k].shape)}"
                   for k, v in matched.items() if v.shape != expected[k].shape]
    if wrong_shape:
        raise ValueError(f"SegFormer weights {path} have tensors of the wrong shape: {wrong_shape[:10]}")
    model.load_state_dict(matched, strict=False)
    return model


def segment_logits(model: SegformerForSemanticSegmentation, images: torch.Tensor) -> torch.Tensor:
    """Per-pixel class logits at the input resolution.

    Args:
        model: a SegFormer; its mode (train/eval) and grad state are the caller's choice, so the
            co-design can backpropagate through this to the lens.
        images: (B, 3, H, W) RGB in [0, 1]. ImageNet mean/std normalisation is applied here,
            so callers pass sensor images as they are.

    Returns:
        (B, num_labels, H, W) logits: the model's 1/4-resolution logits bilinearly upsampled
        (align_corners=False, as SegFormer's inference does; by matrix products when a gradient flows,
        `resize_for_training`).
    """
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(f"images must be (B, 3, H, W) RGB in [0, 1], got shape {tuple(images.shape)}")
    mean = images.new_tensor(IMAGENET_MEAN).view(1, 3, 1, 1)
    std = images.new_tensor(IMAGENET_STD).view(1, 3, 1, 1)
    logits = model(pixel_values=(images - mean) / std).logits
    return resize_for_training(logits, images.shape[-2:])


def _window_starts(size: int, window: int, stride: int) -> list[int]:
    """Start offsets of windows covering [0, size); the last one is shifted back to end at size."""
    n = max(size - window + stride - 1, 0) // stride + 1
    return [max(min(i * stride + window, size) - window, 0) for i in range(n)]


def sliding_window_logits(
    model: SegformerForSemanticSegmentation,
    image: torch.Tensor,
    *,
    window: tuple[int, int],
    stride: tuple[int, int],
    logits: Callable[[torch.Tensor], torch.Tensor] | None = None,
) -> torch.Tensor:
    """Full-resolution logits from overlapping windows, as SegFormer's sliding inference.

    Windows of ``window`` pixels are taken every ``stride`` pixels (the last row/column of
    windows is shifted to end at the image border); each window's upsampled logits
    (:func:`segment_logits`) are summed into place and divided by how many windows covered
    each pixel. An image smaller than the window is processed whole. SegFormer on Cityscapes
    uses window (1024, 1024), stride (768, 768); a model trained on 512 crops should use 512.

    Args:
        model: a SegFormer (put it in eval mode for inference).
        image: (B, 3, H, W) RGB in [0, 1].
        window: (height, width) of a window in pixels.
        stride: (vertical, horizontal) step between windows in pixels, at most the window.
        logits: full-size logits of a batch of windows (B, 3, h, w) -> (B, num_labels, h, w);
            default :func:`segment_logits` with ``model`` (an ONNX Runtime engine of the same
            model, :mod:`benchmark.codesign.utility.segformer_onnx`, gives the same within 1e-4).

    Returns:
        (B, num_labels, H, W) averaged logits.
    """
    (win_h, win_w), (step_h, step_w) = window, stride
    if not (0 < step_h <= win_h and 0 < step_w <= win_w):
        raise ValueError(f"stride {stride} must be positive and at most the window {window}, or pixels are skipped")
    window_logits = logits or (lambda crop: segment_logits(model, crop))
    b, _, h, w = image.shape
    total = image.new_zeros(b, model.config.num_labels, h, w)
    count = image.new_zeros(1, 1, h, w)
    for y in _window_starts(h, win_h, step_h):
        for x in _window_starts(w, win_w, step_w):
            y2, x2 = min(y + win_h, h), min(x + win_w, w)
            # In-place add into the window's slice: autograd records it (copy-slices), and the sum is
            # bit-identical to padding every window to the full image, without a full-size tensor
            # per window, and faster (docs/history.md).
            total[:, :, y:y2, x:x2] += window_logits(image[:, :, y:y2, x:x2])
            count[:, :, y:y2, x:x2] += 1
    return total / count
