"""Where artifacts live and what made them: the content-addressed cache (``cache``), the provenance
stamped on every row (``provenance``), the run profiles, every size, count and step budget
(``profiles``), and the shipped table of measured costs (``measured_costs``). The bottom floor of ``benchmark``: imports nothing else of it."""
