"""Data-parallel co-design on two gloo ranks: it computes the single-process run on the same global
batches (within float reduction order), keeps the ranks bitwise in sync, resumes, and only rank 0 writes."""

import dataclasses
import os
import re
import socket
from pathlib import Path

import pytest
import torch
import torch.distributed as dist
import torch.multiprocessing as mp

from benchmark.codesign.codesigned_lenses import START_SPEC
from benchmark.codesign.schemes import SCHEMES
from benchmark.codesign.trainer import CoDesign
from benchmark.store.profiles import PROFILES
from lenses.spec import load_spec

pytestmark = pytest.mark.slow  # two spawned gloo ranks co-design (about a minute)

# test_codesign's tiny profile with two rows per rank: CPU kernels lay out a one-row activation
# differently, and dropout masks follow the layout (see distributed._GlobalDropout).
TINY = dataclasses.replace(PROFILES["smoke"], image_size=(64, 128), n_train=2, train_crop=(48, 48), batch_size=4,
                           codesign_steps=2, pretrain_steps=1, utility_model="tiny", adversary_width=4)
# Differences come from float reduction order only (sums split over ranks, batch-norm statistics
# from all-reduced sums in float64): after two steps the utility weights differ by <= 1e-6, except
# the weights of GAUGE. The coefficients' second Adam step (lr 2e-2 um) divides the two steps'
# gradients, so rounding moves it further, by a CPU-dependent amount: for os-d-1, two ranks against
# one process (one thread each) measured 6e-6 um on MKL's AVX2 path and 1.7e-4 um on its AVX-512
# path (gp: <= 1e-7), and one process alone moves 1e-4 um between ATen's AVX2 and AVX-512 kernels.
# COEFFICIENT_ATOL is 5 % of one step; another global batch moves them by a sizeable part of lr.
ATOL = 1e-5
COEFFICIENT_ATOL = 1e-3
# Weights whose gradient is zero in exact arithmetic: per-channel constants that the decode head's
# batch norm subtracts again (the projection biases, the last encoder stage's layer-norm bias) and
# the running mean that tracks them. Their gradients are rounding noise, which Adam turns into
# steps of up to lr either way, in one process as in two, so they are only bounded.
GAUGE = re.compile(r"decode_head\.linear_projections\.\d+\.proj\.bias|segformer\.stages\.3\.layer_norm\.bias"
                   r"|decode_head\.batch_norm\.running_mean")
WORLD = 2
ADAM_BOUND = 2 * TINY.seg_lr * TINY.codesign_steps
WRITERS = ("save_checkpoint", "save_weights", "publish_directory", "write_json")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _flat(module: torch.nn.Module) -> torch.Tensor:
    return torch.cat([t.detach().flatten().float() for t in module.state_dict().values()])


def _worker(rank: int, port: int, root: Path) -> None:
    os.environ.update(MASTER_ADDR="127.0.0.1", MASTER_PORT=str(port))
    torch.set_num_threads(1)
    dist.init_process_group("gloo", rank=rank, world_size=WORLD)
    from benchmark.codesign import trainer
    from benchmark.codesign.distributed import DataParallel
    writes: list[str] = []
    for name in WRITERS:  # count every artifact write of this rank
        original = getattr(trainer, name)
        setattr(trainer, name, lambda *a, _f=original, _n=name, **k: (writes.append(_n), _f(*a, **k))[1])
    in_sync: list[bool] = []
    step = trainer.CoDesign._step

    def checked_step(self, i, run_state):
        stats = step(self, i, run_state)
        state = torch.cat([run_state.lens.coefficients_um.detach(), _flat(run_state.seg), _flat(run_state.deb)])
        gathered = [torch.empty_like(state) for _ in range(WORLD)]
        dist.all_gather(gathered, state)
        in_sync.append(all(torch.equal(g, gathered[0]) for g in gathered))
        return stats

    trainer.CoDesign._step = checked_step
    replicas = DataParallel("cpu")
    out = {}
    for scheme in ("os-d-1", "gp"):
        run = CoDesign(load_spec(START_SPEC), SCHEMES[scheme], TINY, 0, "cpu", root / scheme, replicas=replicas)
        if scheme == "gp":  # interrupted after one step, then resumed
            try:
                run.train(progress=False, stop_after=1)
            except KeyboardInterrupt:
                dist.barrier()  # rank 0 has written the checkpoint
                out["gp_checkpoint_step"] = torch.load(run.checkpoint_path, weights_only=True)["step"]
            run = CoDesign(load_spec(START_SPEC), SCHEMES[scheme], TINY, 0, "cpu", root / scheme, replicas=replicas)
        trained = run.train(progress=False)
        out[scheme] = {"coefficients_um": trained.record["final_coefficients_um"], "steps": trained.record["curves"]["step"],
                       "utility": trained.utility_net.state_dict(), "world_size": trained.record["world_size"]}
    out.update(writes=writes, in_sync=in_sync)
    torch.save(out, root / f"rank{rank}.pt")
    dist.destroy_process_group()


@pytest.fixture(scope="module")
def ranks(tmp_path_factory):
    root = tmp_path_factory.mktemp("ddp")
    mp.spawn(_worker, args=(_free_port(), root), nprocs=WORLD, join=True)
    return root, [torch.load(root / f"rank{r}.pt", weights_only=True) for r in range(WORLD)]


@pytest.mark.parametrize("scheme", ["os-d-1", "gp"])
def test_two_ranks_compute_the_single_process_run(ranks, scheme, tmp_path):
    _, results = ranks
    # One thread, as each rank: BLAS splits its sums by thread count too (measured, one process, MKL's
    # AVX2 path: 20 % of the utility weights move by more than ATOL between 1 and 2 threads).
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        single = CoDesign(load_spec(START_SPEC), SCHEMES[scheme], TINY, 0, "cpu", tmp_path).train(progress=False)
    finally:
        torch.set_num_threads(threads)
    for r in results:
        assert r[scheme]["world_size"] == WORLD
        assert r[scheme]["steps"] == list(range(TINY.codesign_steps))
        torch.testing.assert_close(torch.tensor(r[scheme]["coefficients_um"]),
                                   torch.tensor(single.record["final_coefficients_um"]), atol=COEFFICIENT_ATOL,
                                   rtol=0)
        close, total = 0, 0
        for name, expected in single.utility_net.state_dict().items():
            got, expected = r[scheme]["utility"][name].float(), expected.float()
            # Adam moves any weight by at most ~lr per step, whatever its gradient's rounding.
            torch.testing.assert_close(got, expected, atol=ADAM_BOUND, rtol=0, msg=lambda m, name=name: f"{name}: {m}")
            if not GAUGE.fullmatch(name):
                close += int(((got - expected).abs() <= ATOL).sum())
                total += got.numel()
        # A gradient within rounding of zero lets Adam step either way (as for GAUGE), so a few weights
        # may differ by more than ATOL, though never by more than Adam's step (checked above). Measured:
        # 1 of ~250k with the 3 x 3 pixel sums and the 300-step clean net; 294 of 245 228 (0.12 %,
        # spread over every stage, at most 1.1e-4) for os-d-1 since exact pixel integration, the
        # seeded initial mask and the new clean-net recipe met (the cause is not yet pinned down).
        assert close >= 0.995 * total, f"{total - close} of {total} utility weights differ by more than {ATOL}"
    moved = torch.tensor(single.record["final_coefficients_um"]) - torch.tensor(load_spec(START_SPEC).mask.zernike_um)
    assert float(moved.abs().max()) > 10 * COEFFICIENT_ATOL, "the comparison must see the optics move"


def test_ranks_hold_identical_state_after_every_step(ranks):
    _, results = ranks
    steps = TINY.codesign_steps * 2  # os-d-1, then gp (one step, interrupted; one step resumed)
    for r in results:
        assert r["in_sync"] == [True] * steps


def test_only_rank_0_writes_and_resume_reads_its_checkpoint(ranks):
    root, (first, second) = ranks
    assert second["writes"] == []
    assert {"save_checkpoint", "publish_directory", "save_weights", "write_json"} <= set(first["writes"])
    assert first["gp_checkpoint_step"] == second["gp_checkpoint_step"] == 1
    for scheme in ("os-d-1", "gp"):
        codesign = root / scheme / "codesign"
        assert [p.name for p in codesign.iterdir() if "staging" in p.name or p.suffix == ".pt"] == []
        (published,) = codesign.iterdir()
        files = {"lens.toml", "utility.safetensors", "adversary.safetensors", "record.json", "curves.jsonl", "curves.png"}
        assert {p.name for p in published.iterdir()} == files | {f + ".sha256" for f in files} | {"tensorboard"}
