"""The co-design step timing study runs the suite's own trainer steps and summarises what it timed."""

import pytest

from benchmark.store.profiles import get_profile
from benchmark.studies.codesign_speed import time_codesign_steps


def test_times_real_steps_of_the_profile_and_leaves_warmup_out():
    result = time_codesign_steps("smoke", "cpu", steps=2, warmup=1)
    smoke = get_profile("smoke")
    assert len(result["step_seconds"]) == 3 and all(s > 0 for s in result["step_seconds"])
    timed = result["step_seconds"][1:]
    assert result["min_s_per_step"] == min(timed) and result["max_s_per_step"] == max(timed)
    assert min(timed) <= result["median_s_per_step"] <= max(timed)
    assert result["crops_per_s"] == pytest.approx(smoke.batch_size / result["median_s_per_step"])
    assert tuple(result["train_crop"]) == smoke.train_crop and result["batch_size"] == smoke.batch_size
    # the steps trained the optics, as co-design does (gp: the adversary's gradient penalty acts too)
    assert result["final_coefficients_um"] != result["initial_coefficients_um"]
    assert "torch_cuda_peak_mib" not in result


def test_rejects_no_timed_steps():
    with pytest.raises(ValueError, match="steps must be >= 1"):
        time_codesign_steps("smoke", "cpu", steps=0)
