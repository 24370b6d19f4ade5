"""Experiments: grids of evaluation cells (`compare`, `cells`), the paper's reproduction (`reproduce`, `paper`,
`report`, `figures`) and the run tools (`select`, `curves`), and model cards (`card`, the one writer of shipped and
zoo cards). The bench and its leaderboard, built on these grids, are a room of their own above: `zodrive.bench`."""
