"""Measuring the run itself: where time and memory go (``profiling``, ``memory_sampler``), the bound
on torch's native memory (``native_memory``) and the library warnings known to be harmless
(``known_warnings``)."""
