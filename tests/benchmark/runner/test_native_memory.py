"""oneDNN's primitive cache is bounded once `benchmark` is imported, and that bounds what networks run
on inputs of many distinct sizes (what the plate windows are) keep alive.

The cache is observed directly: oneDNN's verbose log says whether building a primitive hit its cache,
and glibc's ``mallinfo2`` counts the bytes still allocated. The resident size is not used: it holds
the free heap the allocator keeps (one CI machine grew 344 MiB bounded and 20 MiB unbounded, this
one 100-340 and 470-700 MiB, while the live bytes grew 6 and 12 MiB)."""

import os
import subprocess
import sys
import textwrap

import pytest

from benchmark.runner.diagnostics import native_memory

pytestmark = pytest.mark.slow  # measures memory in fresh Python subprocesses

SHAPES = 300  # distinct input shapes, more than the bounded capacity (128 primitives)
GROWTH = textwrap.dedent(f"""
    import benchmark, os, torch  # importing benchmark bounds the cache
    from benchmark.runner.diagnostics.native_memory import live_heap_bytes as live
    torch.set_num_threads(1)
    net = torch.nn.Sequential(*[torch.nn.Conv2d(64, 64, 3, padding=1) for _ in range(2)]).eval()
    with torch.no_grad():
        net(torch.rand(1, 64, 16, 32))
        start = live()
        for i in range(1, {SHAPES}):
            net(torch.rand(1, 64, 16 + i, 32))
        grown = live() - start
        print("REPEAT", flush=True)
        net(torch.rand(1, 64, 16, 32))  # the first shape again: still cached, or evicted long ago
    print("RESULT", os.environ["ONEDNN_PRIMITIVE_CACHE_CAPACITY"], grown / 2**20, flush=True)
""")


def _run(env_value: str | None) -> tuple[str, str, float]:
    """(capacity, how oneDNN built the repeated shape's first convolution, live MiB grown)."""
    env = {k: v for k, v in os.environ.items() if k != native_memory.ONEDNN_CACHE_VARIABLE}
    env["ONEDNN_VERBOSE"] = "2"  # log each primitive's creation, with cache_hit or cache_miss
    if env_value is not None:
        env[native_memory.ONEDNN_CACHE_VARIABLE] = env_value
    out = subprocess.run([sys.executable, "-c", GROWTH], env=env, capture_output=True, text=True, timeout=300,
                         check=True).stdout
    repeated = [line for line in out.split("REPEAT", 1)[-1].splitlines() if ",convolution," in line]
    assert repeated, f"oneDNN built no convolution for the repeated shape; torch no longer runs convs on it?\n{out[-2000:]}"
    creation = next(field for field in repeated[0].split(",") if field.startswith("create:"))
    _, capacity, grown = out[out.rindex("RESULT"):].split()
    return capacity, creation, float(grown)


@pytest.mark.skipif(native_memory.live_heap_bytes() is None, reason="needs glibc >= 2.33 (mallinfo2)")
def test_importing_benchmark_bounds_the_cache_and_keeps_a_user_setting():
    assert os.environ[native_memory.ONEDNN_CACHE_VARIABLE]  # this process imported benchmark
    bounded_capacity, bounded_creation, bounded = _run(None)
    default_capacity, default_creation, unbounded = _run("1024")  # oneDNN's own default, as a user could ask for
    assert bounded_capacity == str(native_memory.ONEDNN_CACHE_CAPACITY) and default_capacity == "1024"
    # 300 shapes later, the bounded cache has evicted the first one; the default still holds it.
    assert (bounded_creation, default_creation) == ("create:cache_miss", "create:cache_hit")
    # What the cached primitives keep alive: measured 8.2 against 18.3 MiB (6.6 with no cache; torch
    # 2.14.1, AVX-512; the same to 0.01 MiB in 3 runs each).
    assert bounded < 0.7 * unbounded, (bounded, unbounded)


HELD = textwrap.dedent("""
    import gc, torch
    from benchmark.runner.diagnostics.memory_sampler import current_rss_mib
    from benchmark.runner.diagnostics.native_memory import release_free_memory
    big = torch.ones(16 * 2**20 // 4)  # freeing one 16 MB mapping raises glibc's mmap threshold to 16 MB
    del big
    start = current_rss_mib()
    blocks = [torch.ones(4 * 2**20 // 4) for _ in range(100)]  # 400 MB, now from the heap
    held = current_rss_mib() - start
    del blocks[::2]  # 200 MB freed in holes between blocks still in use, as a task leaves its heap
    gc.collect()
    kept = current_rss_mib() - start
    released = release_free_memory()
    print(held, kept, current_rss_mib() - start, released)
""")


def test_released_memory_goes_back_to_the_system():
    out = subprocess.run([sys.executable, "-c", HELD], capture_output=True, text=True, timeout=300, check=True)
    held, kept, after, released = (float(v) if v[0].isdigit() else v for v in out.stdout.split())
    assert released == "True"  # Linux with glibc: what CI and this machine run
    # Freed, the holes stay resident in the allocator's heap; released, they go (the other half stays in use).
    assert held > 380 and kept > 0.9 * held, out.stdout
    assert after < kept - 150, out.stdout
