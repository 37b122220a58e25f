"""What leaves a run for others: the leaderboard (entries merged and published, its tables, the
paper's findings, the report and the web page) and the trained artifacts shipped in the package
(``ship_lens``, ``ship_attacker``). The top floor below the API and the CLI."""
