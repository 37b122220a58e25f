"""What one run does, in order: its config, the plan of tasks, their execution (here or on Ray),
scenes through the lens (``sensing``), the attack and scoring of one lens (``evaluation``), rows and
their intervals, the run's pictures, and the diagnostics that measure the run itself
(``diagnostics/``). Imports the floors below it (``store``, ``scenes``, ``results``, ``codesign``),
never ``studies`` or ``publish``."""
