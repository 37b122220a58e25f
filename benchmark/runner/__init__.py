"""What one run does, in order: its config (``config``; the default attack set in ``defaults``,
attackers given as objects in ``attacker_objects``), the plan of tasks (``planning``) and their bodies
(``tasks``), their execution here or on Ray (``executors``; ``runner`` ties these together), scenes
through the lens (``sensing``), the attack and scoring of one lens (``evaluation``; each attacker kept
apart by ``isolation``, an expensive step bounded by ``budget``) and its utility (``utility_measure``),
rows and their intervals (``rows``, ``intervals``), the run's pictures (``pictures``), what each task
cost (``task_costs``), and the diagnostics that measure the run itself (``diagnostics/``). Imports the
floors below it (``store``, ``scenes``, ``results``, ``codesign``), never ``studies`` or ``publish``."""
