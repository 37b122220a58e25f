"""The gradient penalty: the default is scale-free (um -> nm leaves a step unchanged), the literal
option is the paper's eq. 4 (checked against a hand-computed gradient on a toy lens)."""

import dataclasses

import pytest
import torch
import torch.nn.functional as F
from torch.func import functional_call

from benchmark.codesign.adversary import build_adversary
from benchmark.codesign.balancing import GradientPenalty, OpticsContext
from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.coefficients import initial_coefficients
from benchmark.codesign.data import step_generator
from benchmark.codesign.replicas import SingleProcess
from benchmark.codesign.utility.segformer import build_segformer, segment_logits
from lenses.lens import Lens
from lenses.spec import load_spec

LR_UM, EPS = 0.02, 1e-8


def _optics_step(balance: GradientPenalty, um_per_unit: float) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """One optics step of a real lens, with the coefficients held in a unit of um_per_unit um.

    Returns (gradient w.r.t. the coefficients in um after converting from the unit, coefficients in
    um after one Adam step whose lr and eps are expressed in the same unit and the projection onto
    the bounds, as the trainer does, stats)."""
    start = load_spec(START_SPEC)
    spec = dataclasses.replace(start, mask=dataclasses.replace(start.mask, zernike_um=initial_coefficients(start, 0)))
    torch.manual_seed(0)
    lens, seg, deb = Lens(spec), build_segformer("tiny").eval(), build_adversary(4)
    deb.decoder[-1].weight.data.normal_(0, 0.05)  # a trained adversary's last layer is not zero
    x = torch.rand(2, 3, 48, 48)
    y = torch.randint(0, 19, (2, 48, 48))
    theta = (lens.coefficients_um.detach() / um_per_unit).requires_grad_()
    sensor = functional_call(lens, {"coefficients_um": theta * um_per_unit}, (x,),
                             {"generator": step_generator(0, 0, "cpu")})
    ctx = OpticsContext(theta, F.cross_entropy(segment_logits(seg, sensor), y), F.mse_loss(deb(sensor), x), lens,
                        SingleProcess())
    terms, stats = balance.optics_terms(ctx)
    gradient_um = torch.stack(terms).sum(0) / um_per_unit
    opt = torch.optim.Adam([theta], lr=LR_UM / um_per_unit, eps=EPS / um_per_unit)
    balance.apply(opt, terms, ctx)
    lo, hi = (torch.tensor(b) for b in zip(*spec.mask.bounds_um))
    return gradient_um, torch.clamp(theta.detach() * um_per_unit, lo, hi), stats


@pytest.fixture(scope="module")
def steps():
    return {(scale_free, unit): _optics_step(GradientPenalty(lambda_deb=1.0, scale_free=scale_free), unit)
            for scale_free in (True, False) for unit in (1.0, 1e-3)}


def test_scale_free_step_is_the_same_in_um_and_nm(steps):
    g_um, after_um, stats_um = steps[True, 1.0]
    g_nm, after_nm, stats_nm = steps[True, 1e-3]
    assert stats_um["penalty"] == pytest.approx(stats_nm["penalty"], rel=1e-4)
    torch.testing.assert_close(g_nm, g_um, rtol=1e-3, atol=1e-3 * float(g_um.abs().max()))
    torch.testing.assert_close(after_nm, after_um, rtol=0, atol=1e-6)
    start = torch.tensor(initial_coefficients(load_spec(START_SPEC), 0), dtype=torch.float32)
    assert float((after_um - start).abs().max()) > 1e-3, "the step must move the optics"
    assert stats_um["penalty"] > 1e-3, "a penalty that is ~0 would make the comparison empty"


def test_literal_penalty_depends_on_the_unit(steps):
    # The same check fails for eq. 4 as printed: this test can tell the two apart.
    g_um, _, stats_um = steps[False, 1.0]
    g_nm, _, stats_nm = steps[False, 1e-3]
    assert stats_um["penalty"] != pytest.approx(stats_nm["penalty"], rel=1e-6)
    assert float((g_nm - g_um).norm()) > 1e-2 * float(g_um.norm())


def test_literal_option_is_eq4_on_a_toy_lens():
    """Toy lens: theta (2,) maps to L_seg = ||theta - t||^2 and L_deb = 1/2 theta^T A theta + b^T theta.

    By hand: g = dL_deb/dtheta = A theta + b, P = (||g|| - 1)^2, dP/dtheta = 2 (||g|| - 1) A g / ||g||
    (A symmetric), so the optics gradient is 2 (theta - t) - lambda_deb g + dP/dtheta."""
    theta = torch.tensor([0.3, -0.2], dtype=torch.float64, requires_grad=True)
    t = torch.tensor([1.0, 0.5], dtype=torch.float64)
    a = torch.tensor([[2.0, 0.5], [0.5, 1.0]], dtype=torch.float64)
    b = torch.tensor([0.1, -0.4], dtype=torch.float64)
    lam = 3.0
    ctx = OpticsContext(theta, ((theta - t) ** 2).sum(), 0.5 * theta @ a @ theta + b @ theta, None, SingleProcess())
    terms, stats = GradientPenalty(lambda_deb=lam, scale_free=False).optics_terms(ctx)
    with torch.no_grad():
        g = a @ theta + b
        n = g.norm()
        expected = 2 * (theta - t) - lam * g + 2 * (n - 1) * (a @ g) / n
    torch.testing.assert_close(torch.stack(terms).sum(0), expected, rtol=1e-12, atol=1e-12)
    assert stats["penalty"] == pytest.approx(float((n - 1) ** 2), rel=1e-12)
    assert stats["grad_deb_norm"] == pytest.approx(float(n), rel=1e-12)
