"""Where artifacts live and what made them: the content-addressed cache (``cache``), the provenance
stamped on every row (``provenance``) and the run profiles, every size, count and step budget
(``profiles``). The bottom floor of ``benchmark``: imports nothing else of it."""
