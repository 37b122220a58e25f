"""RED10: shapes, /16 bottleneck, second-order gradients, ability to fit a pair."""

import pytest
import torch
from torch import nn

from attacks.networks.red10 import RED10


@pytest.mark.parametrize("size", [(64, 96), (37, 53), (5, 3)])
def test_output_shape_and_range(size: tuple[int, int]) -> None:
    torch.manual_seed(0)
    y = RED10(width=8)(torch.rand(2, 3, *size))
    assert y.shape == (2, 3, *size)
    assert ((y > 0) & (y < 1)).all()


def test_ten_layers_without_skips() -> None:
    model = RED10(width=8)
    convs = [m for m in model.modules() if isinstance(m, nn.Conv2d)]
    deconvs = [m for m in model.modules() if isinstance(m, nn.ConvTranspose2d)]
    assert len(convs) == 5 and len(deconvs) == 5
    assert [c.stride for c in convs].count((2, 2)) == 4


def test_bottleneck_is_one_sixteenth() -> None:
    model = RED10(width=8)
    seen: list[torch.Size] = []
    model.encoder.register_forward_hook(lambda _m, _i, out: seen.append(out.shape))
    model(torch.rand(1, 3, 64, 96))
    assert seen == [torch.Size([1, 8, 4, 6])]


def test_second_order_gradients_wrt_input_are_finite_and_nonzero() -> None:
    # The gradient penalty differentiates ||dL/dx|| again: this must not be zero or NaN.
    torch.manual_seed(0)
    model = RED10(width=8).double()
    x = torch.rand(1, 3, 20, 24, dtype=torch.float64, requires_grad=True)
    target = torch.rand(1, 3, 20, 24, dtype=torch.float64)
    loss = (model(x) - target).pow(2).mean()
    (g,) = torch.autograd.grad(loss, x, create_graph=True)
    (gg,) = torch.autograd.grad(g.norm(), x)
    assert torch.isfinite(gg).all()
    assert gg.abs().sum() > 0


def test_double_backward_matches_finite_difference() -> None:
    # d/dx ||dL/dx|| along a random direction, against a central difference of ||dL/dx||.
    torch.manual_seed(1)
    model = RED10(width=4).double()
    target = torch.rand(1, 3, 16, 16, dtype=torch.float64)

    def grad_norm(x: torch.Tensor, create_graph: bool) -> torch.Tensor:
        loss = (model(x) - target).pow(2).mean()
        (g,) = torch.autograd.grad(loss, x, create_graph=create_graph)
        return g.norm()

    x = torch.rand(1, 3, 16, 16, dtype=torch.float64, requires_grad=True)
    direction = torch.randn_like(x)
    (gg,) = torch.autograd.grad(grad_norm(x, create_graph=True), x)
    h = 1e-6
    plus = grad_norm((x + h * direction).detach().requires_grad_(), create_graph=False)
    minus = grad_norm((x - h * direction).detach().requires_grad_(), create_graph=False)
    fd = (plus - minus) / (2 * h)
    torch.testing.assert_close((gg * direction).sum(), fd, rtol=1e-4, atol=1e-9)


def test_overfits_one_pair() -> None:
    torch.manual_seed(0)
    model = RED10(width=16)
    sharp = torch.rand(1, 3, 16, 16)
    blurred = torch.nn.functional.avg_pool2d(sharp, 3, stride=1, padding=1, count_include_pad=False)
    opt = torch.optim.Adam(model.parameters(), lr=3e-3)
    first = None
    for _ in range(100):
        loss = (model(blurred) - sharp).pow(2).mean()
        first = loss.item() if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert loss.item() < first / 10
