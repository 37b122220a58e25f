"""The lens forward's OTF cache: it follows the coefficients, and differentiation never uses it."""

import pytest
import torch

from lenses import Lens
from lenses.convolve import convolve
from lenses.spec import parse_spec


def trainable_lens() -> Lens:
    return Lens(parse_spec({"name": "c", "mask": {"zernike_um": [0.0, 0.1, -0.1, 0.4, 0.2, -0.3],
                                                  "bounds_um": [[-1.0, 1.0]] * 6}}))


def uncached_irradiance(lens: Lens, x: torch.Tensor) -> torch.Tensor:
    return convolve(x, lens.psf().to(x.device))


def test_cached_irradiance_equals_uncached_and_is_reused():
    lens = trainable_lens()
    x = torch.rand(2, 3, 40, 56)
    with torch.no_grad():
        first = lens.irradiance(x)
        (entry,) = lens._otf_cache.values()
        again = lens.irradiance(x)
        torch.testing.assert_close(first, uncached_irradiance(lens, x), atol=1e-6, rtol=0)
    assert torch.equal(first, again) and next(iter(lens._otf_cache.values()))[1] is entry[1]
    with torch.no_grad():
        lens.irradiance(torch.rand(1, 3, 30, 30))  # another image size: its own entry
    assert len(lens._otf_cache) == 2


def test_new_image_sizes_reuse_one_psf_until_the_coefficients_change(monkeypatch):
    lens = trainable_lens()
    calls = []
    pupil = lens.pupil.forward
    monkeypatch.setattr(lens.pupil, "forward", lambda c: calls.append(1) or pupil(c))
    with torch.no_grad():
        for size in (30, 34, 38, 42):  # plate windows: many sizes, one PSF
            lens.irradiance(torch.rand(1, 3, size, size + 4))
        assert len(calls) == 1
        lens.coefficients_um.add_(0.05)
        after = lens.irradiance(torch.rand(1, 3, 30, 34))
    assert len(calls) == 2
    x = torch.rand(1, 3, 46, 50)
    with torch.no_grad():
        torch.testing.assert_close(lens.irradiance(x), uncached_irradiance(lens, x), atol=1e-6, rtol=0)
    assert after.shape == (1, 3, 30, 34)


def test_training_step_sees_the_new_otf_and_gradients_match_the_uncached_path():
    lens = trainable_lens()
    x = torch.rand(2, 3, 40, 56, generator=torch.Generator().manual_seed(1))
    target = torch.rand(2, 3, 40, 56, generator=torch.Generator().manual_seed(2))
    with torch.no_grad():
        before = lens.irradiance(x)  # fills the cache
    # A training step: the differentiated forward bypasses the cache and must give the uncached gradient.
    loss = ((lens.irradiance(x) - target) ** 2).mean()
    (grad,) = torch.autograd.grad(loss, lens.coefficients_um)
    (reference,) = torch.autograd.grad(((uncached_irradiance(lens, x) - target) ** 2).mean(), lens.coefficients_um)
    torch.testing.assert_close(grad, reference, rtol=0, atol=0)
    assert float(grad.abs().sum()) > 0
    optimiser = torch.optim.SGD([lens.coefficients_um], lr=0.5)
    lens.coefficients_um.grad = grad
    optimiser.step()
    with torch.no_grad():
        after = lens.irradiance(x)
        torch.testing.assert_close(after, uncached_irradiance(lens, x), atol=1e-6, rtol=0)
    assert float((after - before).abs().max()) > 1e-3  # the step changed the image, and the cache saw it


def test_second_order_gradient_through_the_forward_is_unchanged_by_the_cache():
    lens = trainable_lens()
    x = torch.rand(1, 3, 36, 36, generator=torch.Generator().manual_seed(3))
    with torch.no_grad():
        lens.irradiance(x)  # a stale cache entry must not leak into the double backward

    def penalty(irradiance):
        (g,) = torch.autograd.grad((irradiance(lens, x) ** 2).mean(), lens.coefficients_um, create_graph=True)
        return torch.autograd.grad((g.norm() - 1) ** 2, lens.coefficients_um)[0]

    torch.testing.assert_close(penalty(Lens.irradiance), penalty(uncached_irradiance), rtol=0, atol=0)


@pytest.mark.parametrize("name", ["ideal", "random-zernike"])
def test_fixed_lens_under_grad_mode_uses_the_cache_and_passes_input_gradients(name):
    import lenses
    lens = lenses.load(name)
    x = torch.rand(1, 3, 32, 48, requires_grad=True)
    with torch.inference_mode():
        lens.irradiance(x.detach())  # an entry made in inference mode must still serve autograd later
    y = lens.irradiance(x)
    (gx,) = torch.autograd.grad(y.sum(), x)
    assert torch.isfinite(gx).all() and float(gx.abs().sum()) > 0
