"""What a result is and how it is judged: the typed row schema (``schema``), restoration metrics
(``metrics``), plate scoring (``plate_scoring``, from the width ``readable_start`` measured), sampling
statistics (``stats``, the pooled intervals of ``pooled``), the leaderboard's entry format and its checks
(``entries``, ``entry_checks``), the ensembles over attackers and the choice of the standard one
(``ensemble``, ``ensemble_choice``), the attack gap (``attack_gap``), a run's tables (``run_tables``;
user text made inert in Markdown by ``markdown``), the ideal observer's ceiling (``observer/``) and every
chart (``charts/``). Imports only ``store`` and ``scenes``."""
