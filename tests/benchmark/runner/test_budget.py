"""The time budget ends a step that runs too long, with a message naming it."""

import threading
import time

import pytest

from benchmark.runner.budget import BudgetExceeded, time_budget
from benchmark.runner.evaluation import attempt


def test_a_step_past_its_budget_is_ended_with_its_name():
    t0 = time.perf_counter()
    with pytest.raises(BudgetExceeded, match=r"the bound of lens 'dark' ran past its budget of 0.2 s"):
        with time_budget(0.2, "the bound of lens 'dark'"):
            time.sleep(30)
    assert time.perf_counter() - t0 < 5


def test_a_step_within_its_budget_is_untouched_and_the_timer_is_cleared():
    with time_budget(5, "quick"):
        time.sleep(0.05)
    time.sleep(0.1)  # no stray alarm afterwards


def test_no_budget_and_other_threads_run_unbounded():
    with time_budget(None, "x"):
        time.sleep(0.05)
    errors = []

    def worker():
        try:
            with time_budget(0.01, "x"):
                time.sleep(0.1)
        except BaseException as exc:  # noqa: BLE001 - the test records anything
            errors.append(exc)

    t = threading.Thread(target=worker)
    t.start()
    t.join()
    assert errors == []


def test_an_attacker_past_its_budget_is_a_failed_row_error():
    error = attempt("slow", "fit", lambda: time.sleep(30), budget_s=0.2)
    assert error.attacker == "slow" and error.stage == "fit" and "budget of 0.2 s" in error.message


def test_a_native_call_that_overruns_the_budget_is_named_in_the_message():
    """The budget is a signal: one long C call (here a key derivation that holds no Python code) runs
    to its end first, and the message says how long the step really took and why."""
    import hashlib
    hashlib.pbkdf2_hmac("sha256", b"p", b"s", 20_000)  # warm: the first call runs slower than the rest
    t0 = time.perf_counter()
    hashlib.pbkdf2_hmac("sha256", b"p", b"s", 100_000)
    rounds = int(100_000 * 2.0 / max(time.perf_counter() - t0, 1e-4))  # about 2 s in one C call
    with pytest.raises(BudgetExceeded) as stop:
        with time_budget(0.2, "restore"):
            hashlib.pbkdf2_hmac("sha256", b"p", b"s", rounds)
    message = str(stop.value)
    spent = float(message.split("was stopped after ")[1].split(" s")[0])
    assert spent >= 0.9, message
    assert "a native call that was running finished first" in message and "past the budget" in message


def test_a_lens_task_past_its_budget_names_the_lens(monkeypatch, tmp_path):
    """The co-design of a lens is covered too: a lens task that raises gives the lens's failed rows."""
    from benchmark.runner import tasks
    from benchmark.runner.config import RunConfig
    from benchmark.runner.planning import Task
    from benchmark.store.profiles import get_profile
    monkeypatch.setattr(tasks, "_lens", lambda cfg, name, seed: time.sleep(30))
    cfg = RunConfig(lenses=["gp"], attacks=[], scenes="synthetic", profile=get_profile("smoke"), seeds=[0],
                    cache_dir=tmp_path, budget_s=0.2)
    t0 = time.perf_counter()
    with pytest.raises(BudgetExceeded, match=r"lens 'gp' \(its co-design or load\) ran past its budget of 0.2 s"):
        tasks._lens_task(Task("lens", 0, "gp"), cfg, tmp_path)
    assert time.perf_counter() - t0 < 5
