"""What a result is and how it is judged: the typed row schema, restoration metrics, plate scoring,
sampling statistics, the leaderboard's entry format, the ideal observer's ceiling (``observer/``)
and every chart (``charts/``). Imports only ``store`` and ``scenes``."""
