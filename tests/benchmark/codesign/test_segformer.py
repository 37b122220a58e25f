"""SegFormer utility model: offline construction, parameter counts, local weight loading,
full-resolution and sliding-window logits."""

import os
import re
import socket
from pathlib import Path

import pytest
import torch
from safetensors.torch import save_file

from benchmark.codesign.utility.segformer import _window_starts, build_segformer, load_segformer_weights, segment_logits, sliding_window_logits


@pytest.fixture(autouse=True)
def no_network(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*_args: object, **_kwargs: object) -> None:
        raise OSError("network access attempted in an offline test")

    monkeypatch.setattr(socket.socket, "connect", refuse)


def _mit_parameter_count(hidden: list[int], heads_unused: list[int], decoder: int, num_labels: int) -> int:
    """Parameters of SegFormer (MiT encoder + all-MLP decoder) from its published layout."""
    patch, sr, depth, mlp = [7, 3, 3, 3], [8, 4, 2, 1], 2, 4
    total, c_in = 0, 3
    for c, k, r in zip(hidden, patch, sr):
        total += c_in * c * k * k + c + 2 * c  # overlapping patch embedding conv + its LayerNorm
        block = 2 * c  # LayerNorm before attention
        block += 4 * (c * c + c)  # query, key, value, output projection
        if r > 1:
            block += c * c * r * r + c + 2 * c  # spatial-reduction conv + LayerNorm
        block += 2 * c  # LayerNorm before Mix-FFN
        block += (c * mlp * c + mlp * c) + (mlp * c * 9 + mlp * c) + (mlp * c * c + c)  # fc1, 3x3 depthwise, fc2
        total += depth * block + 2 * c  # blocks + stage LayerNorm
        c_in = c
    total += sum(c * decoder + decoder for c in hidden)  # per-stage linear projections
    total += 4 * decoder * decoder + 2 * decoder  # fuse 1x1 conv (no bias) + BatchNorm
    total += decoder * num_labels + num_labels  # classifier
    return total


def _n_params(model: torch.nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def test_built_offline() -> None:
    assert os.environ["HF_HUB_OFFLINE"] == "1"
    model = build_segformer("b0")
    assert model.config.hidden_sizes == [32, 64, 160, 256]
    assert model.config.num_labels == 19


def test_b0_parameter_count() -> None:
    expected = _mit_parameter_count([32, 64, 160, 256], [1, 2, 5, 8], 256, 19)
    assert _n_params(build_segformer("b0", num_labels=19)) == expected
    assert abs(expected - 3.72e6) < 0.01e6
    # Xie et al. 2021 report 3.8 M for B0 with ADE20K's 150-class head.
    assert abs(_mit_parameter_count([32, 64, 160, 256], [1, 2, 5, 8], 256, 150) - 3.8e6) < 0.05e6


def test_narrow_parameter_count() -> None:
    expected = _mit_parameter_count([16, 32, 80, 128], [1, 1, 2, 4], 128, 19)
    assert _n_params(build_segformer("b0-narrow")) == expected


def test_unknown_variant() -> None:
    with pytest.raises(ValueError, match="b7.*valid"):
        build_segformer("b7")


def test_safetensors_round_trip(tmp_path: Path) -> None:
    torch.manual_seed(0)
    source = build_segformer("b0").eval()
    path = tmp_path / "b0.safetensors"
    save_file({k: v.contiguous() for k, v in source.state_dict().items()}, str(path))
    target = load_segformer_weights(build_segformer("b0"), path).eval()
    x = torch.rand(1, 3, 64, 64)
    with torch.no_grad():
        torch.testing.assert_close(segment_logits(target, x), segment_logits(source, x), rtol=0, atol=0)


def test_pth_with_prefixes_round_trip(tmp_path: Path) -> None:
    source = build_segformer("tiny").eval()
    path = tmp_path / "tiny.pth"
    torch.save({"state_dict": {"module." + k: v for k, v in source.state_dict().items()}}, path)
    target = load_segformer_weights(build_segformer("tiny"), path)
    for k, v in source.state_dict().items():
        assert torch.equal(target.state_dict()[k], v)


def test_save_pretrained_directory_round_trip(tmp_path: Path) -> None:
    source = build_segformer("tiny").eval()
    source.save_pretrained(tmp_path / "tiny")
    target = load_segformer_weights(build_segformer("tiny"), tmp_path / "tiny").eval()
    x = torch.rand(1, 3, 32, 48)
    with torch.no_grad():
        torch.testing.assert_close(segment_logits(target, x), segment_logits(source, x), rtol=0, atol=0)


def test_encoder_only_checkpoint_loads_non_strict(tmp_path: Path) -> None:
    source = build_segformer("tiny")
    encoder = {k.removeprefix("segformer."): v for k, v in source.state_dict().items() if k.startswith("segformer.")}
    path = tmp_path / "encoder.safetensors"
    save_file({k: v.contiguous() for k, v in encoder.items()}, str(path))
    with pytest.raises(ValueError, match="missing keys.*decode_head"):
        load_segformer_weights(build_segformer("tiny"), path)
    target = load_segformer_weights(build_segformer("tiny"), path, strict=False)
    for key, value in source.state_dict().items():
        if key.startswith("segformer."):
            assert torch.equal(target.state_dict()[key], value)


def test_wrong_variant_names_keys(tmp_path: Path) -> None:
    path = tmp_path / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in build_segformer("tiny").state_dict().items()}, str(path))
    with pytest.raises(ValueError, match=r"tiny\.safetensors.*wrong shape.*file \(64,\) vs model \(128,\)"):
        load_segformer_weights(build_segformer("b0-narrow"), path, strict=False)


def _to_legacy_names(key: str) -> str:
    """transformers < 5 names, as in the published nvidia/segformer-* checkpoints."""
    for new, old in [
        (r"stages\.(\d+)\.patch_embeddings\.", r"encoder.patch_embeddings.\1."),
        (r"stages\.(\d+)\.blocks\.", r"encoder.block.\1."),
        (r"stages\.(\d+)\.layer_norm\.", r"encoder.layer_norm.\1."),
        (r"attention\.q_proj\.", "attention.self.query."),
        (r"attention\.k_proj\.", "attention.self.key."),
        (r"attention\.v_proj\.", "attention.self.value."),
        (r"attention\.sequence_reduction\.sequence_reduction\.", "attention.self.sr."),
        (r"attention\.sequence_reduction\.layer_norm\.", "attention.self.layer_norm."),
        (r"attention\.o_proj\.", "attention.output.dense."),
        (r"mlp\.fc1\.", "mlp.dense1."),
        (r"mlp\.fc2\.", "mlp.dense2."),
        (r"layernorm_before\.", "layer_norm_1."),
        (r"layernorm_after\.", "layer_norm_2."),
        (r"linear_projections\.", "linear_c."),
    ]:
        key = re.sub(new, old, key)
    return key


def test_transformers4_names_load(tmp_path: Path) -> None:
    source = build_segformer("tiny")
    legacy = {_to_legacy_names(k): v.contiguous() for k, v in source.state_dict().items()}
    if "segformer.encoder.block.0.1.attention.self.query.weight" not in legacy:
        pytest.skip("this transformers version already uses the legacy names")
    assert {
        "segformer.encoder.patch_embeddings.0.proj.weight",
        "segformer.encoder.block.1.0.attention.self.sr.weight",
        "segformer.encoder.block.3.1.mlp.dense2.bias",
        "segformer.encoder.layer_norm.3.weight",
        "decode_head.linear_c.2.proj.bias",
    } <= set(legacy)
    path = tmp_path / "legacy.safetensors"
    save_file(legacy, str(path))
    target = load_segformer_weights(build_segformer("tiny"), path)
    for k, v in source.state_dict().items():
        assert torch.equal(target.state_dict()[k], v)


def test_hub_name_is_refused_without_download() -> None:
    with pytest.raises(FileNotFoundError, match="nvidia/mit-b0"):
        load_segformer_weights(build_segformer("tiny"), "nvidia/mit-b0")


def test_segment_logits_full_size_and_differentiable() -> None:
    model = build_segformer("tiny").eval()
    x = torch.rand(2, 3, 37, 53, requires_grad=True)
    logits = segment_logits(model, x)
    assert logits.shape == (2, 19, 37, 53)
    logits.logsumexp(dim=1).mean().backward()
    assert x.grad is not None and x.grad.abs().sum() > 0


def test_single_window_equals_plain_forward() -> None:
    model = build_segformer("tiny").eval()
    x = torch.rand(1, 3, 64, 96)
    with torch.no_grad():
        torch.testing.assert_close(
            sliding_window_logits(model, x, window=(64, 96), stride=(64, 96)), segment_logits(model, x)
        )


def test_overlapping_windows_average_their_logits() -> None:
    model = build_segformer("tiny").eval()
    x = torch.rand(1, 3, 32, 80)
    with torch.no_grad():
        slid = sliding_window_logits(model, x, window=(32, 48), stride=(32, 32))
        left, right = segment_logits(model, x[..., :48]), segment_logits(model, x[..., 32:])
    # Windows start at 0 and 32: columns 32..47 are seen by both and averaged.
    torch.testing.assert_close(slid[..., :32], left[..., :32])
    torch.testing.assert_close(slid[..., 32:48], (left[..., 32:] + right[..., :16]) / 2)
    torch.testing.assert_close(slid[..., 48:], right[..., 16:])


@pytest.mark.parametrize("size, window, stride", [(100, 48, 32), (2048, 1024, 768), (30, 48, 32), (64, 64, 64)])
def test_window_starts_cover_the_image(size: int, window: int, stride: int) -> None:
    starts = _window_starts(size, window, stride)
    assert starts[0] == 0 and min(starts[-1] + window, size) == size
    assert all(b - a <= stride for a, b in zip(starts, starts[1:]))  # no gap between windows
