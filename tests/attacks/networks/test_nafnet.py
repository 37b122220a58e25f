"""NAFNet: official layout (names, parameter count), checkpoint loading, shapes, LayerNorm2d."""

from pathlib import Path

import pytest
import torch
from safetensors.torch import save_file

from attacks.networks.nafnet import LayerNorm2d, NAFBlock, NAFNet, load_nafnet_checkpoint

TINY = dict(width=8, middle_blk_num=1, enc_blk_nums=(1, 1, 1, 1), dec_blk_nums=(1, 1, 1, 1))


def _randomized(model: torch.nn.Module, seed: int = 0) -> torch.nn.Module:
    """Give every parameter random values: a fresh NAFNet has beta = gamma = 0, so its blocks are
    identities and an output comparison would not exercise them."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for p in model.parameters():
            p.copy_(0.1 * torch.randn(p.shape, generator=g))
    return model.eval()


@pytest.fixture(scope="module")
def gopro() -> NAFNet:
    return NAFNet(width=32, middle_blk_num=1, enc_blk_nums=(1, 1, 1, 28), dec_blk_nums=(1, 1, 1, 1))


def test_gopro_width32_parameter_count_matches_published(gopro: NAFNet) -> None:
    # Chen et al. 2022, Table / model zoo: NAFNet-GoPro-width32 has 17.11 M parameters.
    n_params = sum(p.numel() for p in gopro.parameters())
    assert abs(n_params - 17.11e6) < 0.01e6


def test_gopro_parameter_count_matches_block_formula(gopro: NAFNet) -> None:
    def block(c: int) -> int:
        # norm1, norm2 (2c each); conv1 c->2c; depthwise 3x3 on 2c; sca c->c; conv3 c->c;
        # conv4 c->2c; conv5 c->c; beta, gamma (c each). Every conv has a bias.
        return 4 * c + (2 * c * c + 2 * c) + (2 * c * 9 + 2 * c) + 3 * (c * c + c) + (2 * c * c + 2 * c) + 2 * c

    width, enc, dec, middle = 32, (1, 1, 1, 28), (1, 1, 1, 1), 1
    total = (3 * width * 9 + width) + (width * 3 * 9 + 3)  # intro, ending
    chan = width
    for n in enc:
        total += n * block(chan) + (chan * 2 * chan * 4 + 2 * chan)  # blocks + 2x2 down conv
        chan *= 2
    total += middle * block(chan)
    for n in dec:
        total += chan * 2 * chan  # 1x1 up conv, no bias
        chan //= 2
        total += n * block(chan)
    assert sum(p.numel() for p in gopro.parameters()) == total


def test_official_parameter_names(gopro: NAFNet) -> None:
    keys = set(gopro.state_dict())
    official = {
        "intro.weight", "ending.weight", "encoders.0.0.conv1.weight", "encoders.0.0.norm1.weight",
        "encoders.0.0.beta", "encoders.0.0.gamma", "encoders.0.0.sca.1.weight", "encoders.3.27.conv2.weight",
        "downs.0.weight", "downs.3.bias", "ups.0.0.weight", "middle_blks.0.conv4.weight",
        "decoders.0.0.conv5.bias", "decoders.3.0.norm2.bias",
    }
    assert official <= keys
    assert "ups.0.0.bias" not in keys  # the official up conv has no bias


def test_checkpoint_with_params_wrapper_loads_strictly(tmp_path: Path) -> None:
    reference = _randomized(NAFNet(**TINY))
    sd = {"module." + k: v for k, v in reference.state_dict().items()}
    path = tmp_path / "nafnet.pth"
    torch.save({"params": sd}, path)
    loaded = load_nafnet_checkpoint(path, **TINY)
    x = torch.rand(1, 3, 32, 48, generator=torch.Generator().manual_seed(1))
    with torch.no_grad():
        torch.testing.assert_close(loaded(x), reference(x), rtol=0, atol=0)


def test_safetensors_checkpoint_loads(tmp_path: Path) -> None:
    reference = _randomized(NAFNet(**TINY), seed=3)
    path = tmp_path / "nafnet.safetensors"
    save_file({k: v.contiguous() for k, v in reference.state_dict().items()}, str(path))
    loaded = load_nafnet_checkpoint(path, **TINY)
    for k, v in reference.state_dict().items():
        assert torch.equal(loaded.state_dict()[k], v)


def test_mismatched_checkpoint_names_path_and_keys(tmp_path: Path) -> None:
    sd = NAFNet(**TINY).state_dict()
    sd.pop("intro.weight")
    sd["extra.weight"] = torch.zeros(1)
    path = tmp_path / "bad.pth"
    torch.save({"params": sd}, path)
    with pytest.raises(ValueError, match=r"bad\.pth.*intro\.weight.*extra\.weight"):
        load_nafnet_checkpoint(path, **TINY)


def test_missing_checkpoint_file(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.pth"):
        load_nafnet_checkpoint(tmp_path / "nope.pth")


def test_odd_sizes_keep_shape() -> None:
    model = _randomized(NAFNet(**TINY))
    x = torch.rand(2, 3, 37, 53)
    with torch.no_grad():
        assert model(x).shape == (2, 3, 37, 53)


def test_fresh_block_is_identity() -> None:
    # beta = gamma = 0 at initialisation, as in the official code: a new block passes x through.
    block = NAFBlock(8)
    x = torch.randn(1, 8, 5, 7)
    torch.testing.assert_close(block(x), x)


def test_tiny_forward_backward() -> None:
    model = _randomized(NAFNet(**TINY)).train()
    x = torch.rand(1, 3, 24, 40, requires_grad=True)
    loss = (model(x) - 0.5).pow(2).mean()
    loss.backward()
    grads = [p.grad for p in model.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert x.grad is not None and x.grad.abs().sum() > 0


def test_layernorm2d_normalises_each_pixels_channels() -> None:
    """Against the definition written out in float64, and its gradients (and their gradients, the
    co-design's gradient penalty differentiates through a gradient) against finite differences."""
    g = torch.Generator().manual_seed(0)
    norm = LayerNorm2d(6)
    with torch.no_grad():
        norm.weight.copy_(torch.randn(6, generator=g))
        norm.bias.copy_(torch.randn(6, generator=g))
    x = 3 * torch.randn(2, 6, 5, 7, generator=g) + 1
    d = x.double()
    centred = d - d.mean(dim=1, keepdim=True)
    y = centred / torch.sqrt(centred.pow(2).mean(dim=1, keepdim=True) + 1e-6)
    expected = norm.weight.double().view(1, -1, 1, 1) * y + norm.bias.double().view(1, -1, 1, 1)
    torch.testing.assert_close(norm(x).double(), expected, rtol=1e-5, atol=1e-5)
    norm64 = norm.double()
    x64 = torch.randn(1, 6, 3, 4, generator=g, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(norm64, (x64,))
    assert torch.autograd.gradgradcheck(norm64, (x64,))
